"""A task as data: the names of its state factors, actions and features, and its encodings.

A :class:`TaskDescription` is what an application (simulator, perception, recordings, robot)
needs to know about a factored tabular task without importing the domain's code: the factors
in the order of the state encoding, the value names of each, the action and feature names, the
flat state index of a factored state, and the pair-observation index ``s * A + a``. It holds
names only (no dynamics) and round-trips through JSON via :meth:`TaskDescription.to_dict`.

The state encoding is row-major (``np.ravel_multi_index`` over ``factor_sizes``): the *first*
factor is the most significant, the last varies fastest.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np

__all__ = ["TaskDescription"]

_DICT_KEYS = ("name", "factors", "action_names", "feature_names")


def _check_name(value: Any, what: str) -> str:
    if not isinstance(value, str):
        raise TypeError(f"{what} must be a str; got {type(value).__name__} {value!r}")
    if not value or value != value.strip():
        raise ValueError(f"{what} must be non-empty without surrounding spaces; got {value!r}")
    return value


def _check_names(values: Any, what: str) -> tuple[str, ...]:
    """A non-empty tuple of distinct names, or raise naming ``what``."""
    if isinstance(values, str | bytes) or not isinstance(values, Iterable):
        raise TypeError(f"{what} must be a sequence of str; got {values!r}")
    names = tuple(values)
    if not names:
        raise ValueError(f"{what} must not be empty; got {names!r}")
    for i, v in enumerate(names):
        _check_name(v, f"{what}[{i}]")
    dupes = sorted({v for v in names if names.count(v) > 1})
    if dupes:
        raise ValueError(f"{what} must be distinct; got duplicates {dupes} in {names!r}")
    return names


def _factor_items(factors: Any) -> list[tuple[Any, Any]]:
    """``factors`` as (name, values) pairs: from a mapping, or a sequence of pairs or of
    ``{"name": ..., "values": ...}`` dicts (the JSON form)."""
    if isinstance(factors, Mapping):
        return list(factors.items())
    if isinstance(factors, str | bytes) or not isinstance(factors, Iterable):
        raise TypeError(f"factors must be a mapping name -> value names; got {factors!r}")
    items = []
    for i, item in enumerate(factors):
        if isinstance(item, Mapping):
            if set(item) != {"name", "values"}:
                raise ValueError(
                    f"factors[{i}] must have exactly the keys 'name' and 'values'; "
                    f"got {sorted(item)}"
                )
            items.append((item["name"], item["values"]))
        elif isinstance(item, Sequence) and not isinstance(item, str) and len(item) == 2:
            items.append((item[0], item[1]))
        else:
            raise TypeError(f"factors[{i}] must be a (name, values) pair; got {item!r}")
    return items


@dataclass(frozen=True, eq=False)
class TaskDescription:
    """The names and encodings of a factored tabular task (data only, JSON-serialisable).

    Parameters
    ----------
    name : str
        The task's name, e.g. ``"onion-sorting"``.
    factors : mapping of str to sequence of str
        Factor name -> the names of its values, in the order of the state encoding (the first
        factor is the most significant). Stored as a read-only mapping of tuples. A sequence of
        ``(name, values)`` pairs is accepted too.
    action_names : sequence of str
        Action ``a`` is ``action_names[a]``.
    feature_names : sequence of str
        Reward feature ``k`` is ``feature_names[k]``.

    Attributes
    ----------
    name : str
    factors : mapping of str to tuple of str
        Read-only.
    action_names, feature_names : tuple of str
    factor_names : tuple of str
        The factors, most significant first.
    factor_sizes : tuple of int
        The number of values of each factor.
    n_states, n_actions, n_features : int
        ``prod(factor_sizes)``, ``len(action_names)``, ``len(feature_names)``.
    n_pairs : int
        ``n_states * n_actions``: the pair observations ``o = s * A + a``.
    state_names : tuple of str
        ``"(v_1, ..., v_F)"`` of each state.

    Examples
    --------
    >>> t = TaskDescription("grid", {"x": ("0", "1", "2"), "y": ("0", "1")},
    ...                     action_names=("left", "right"), feature_names=("goal",))
    >>> t.n_states, t.encode({"x": 2, "y": 1}), t.decode(3), t.state_names[3]
    (6, 5, {'x': 1, 'y': 1}, '(1, 1)')
    >>> t.pair(3, 1), t.unpair(7)
    (7, (3, 1))
    """

    name: str
    factors: Mapping[str, tuple[str, ...]]
    action_names: tuple[str, ...]
    feature_names: tuple[str, ...]

    def __post_init__(self) -> None:
        _check_name(self.name, "name")
        items = _factor_items(self.factors)
        if not items:
            raise ValueError(f"factors must not be empty; got {self.factors!r}")
        factor_names = _check_names([k for k, _ in items], "factor names")
        factors = {
            k: _check_names(v, f"factors[{k!r}]")
            for k, (_, v) in zip(factor_names, items, strict=True)
        }
        object.__setattr__(self, "factors", MappingProxyType(factors))
        object.__setattr__(self, "action_names", _check_names(self.action_names, "action_names"))
        object.__setattr__(
            self, "feature_names", _check_names(self.feature_names, "feature_names")
        )
        sizes = tuple(len(v) for v in factors.values())
        strides = tuple(math.prod(sizes[i + 1:]) for i in range(len(sizes)))
        object.__setattr__(self, "_sizes", sizes)
        object.__setattr__(self, "_strides", strides)

    # -- identity -----------------------------------------------------------------------------

    def _key(self) -> tuple:
        return (self.name, tuple(self.factors.items()), self.action_names, self.feature_names)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, TaskDescription):
            return NotImplemented
        return self._key() == other._key()  # factor order matters: it fixes the encoding

    def __hash__(self) -> int:
        return hash(self._key())

    def __repr__(self) -> str:
        factors = ", ".join(f"{k}={len(v)}" for k, v in self.factors.items())
        return (
            f"TaskDescription(name={self.name!r}, factors=({factors}), "
            f"n_actions={self.n_actions}, n_features={self.n_features})"
        )

    def __reduce__(self):
        # the read-only factor mapping does not pickle; rebuild from plain data
        return (type(self), (self.name, dict(self.factors), self.action_names,
                             self.feature_names))

    # -- sizes and names ----------------------------------------------------------------------

    @property
    def factor_names(self) -> tuple[str, ...]:
        """The factor names, most significant first."""
        return tuple(self.factors)

    @property
    def factor_sizes(self) -> tuple[int, ...]:
        """Number of values of each factor, shape (F,)."""
        return self._sizes

    @property
    def n_states(self) -> int:
        """``prod(factor_sizes)``."""
        return math.prod(self._sizes)

    @property
    def n_actions(self) -> int:
        return len(self.action_names)

    @property
    def n_features(self) -> int:
        return len(self.feature_names)

    @property
    def n_pairs(self) -> int:
        """Number of ``(s, a)`` pair-observation indices, ``n_states * n_actions``."""
        return self.n_states * self.n_actions

    @property
    def state_names(self) -> tuple[str, ...]:
        """``state_names[s]`` is ``"(v_1, ..., v_F)"``, the value names of state ``s``."""
        return tuple(self.state_name(s) for s in range(self.n_states))

    def state_name(self, s: int) -> str:
        """The name ``"(v_1, ..., v_F)"`` of state ``s``."""
        values = self.decode(s)
        return "(" + ", ".join(self.factors[f][i] for f, i in values.items()) + ")"

    def value_name(self, factor: str, index: int) -> str:
        """The name of value ``index`` of ``factor``."""
        values = self._factor(factor)
        i = self._index(index, len(values), f"index of factor {factor!r}")
        return values[i]

    def value_index(self, factor: str, value: str) -> int:
        """The index of the value named ``value`` of ``factor``."""
        values = self._factor(factor)
        if value not in values:
            raise ValueError(f"value of factor {factor!r} must be one of {values}; got {value!r}")
        return values.index(value)

    def action_index(self, action: str) -> int:
        """The index of the action named ``action``."""
        if action not in self.action_names:
            raise ValueError(f"action must be one of {self.action_names}; got {action!r}")
        return self.action_names.index(action)

    # -- state encoding -----------------------------------------------------------------------

    def encode(self, values: Mapping[str, int | str] | Sequence[int]) -> int:
        """The flat state index of one factored state.

        Parameters
        ----------
        values : mapping of str to int or str, or sequence of int of length F
            Factor name -> value index (or value name); or the value indices in factor order.

        Returns
        -------
        int
            ``sum_f values[f] * prod(factor_sizes[f + 1:])`` (row-major).
        """
        if isinstance(values, Mapping):
            if set(values) != set(self.factors):
                raise ValueError(
                    f"values must name exactly the factors {self.factor_names}; "
                    f"got {tuple(values)}"
                )
            indices = [
                self.value_index(f, values[f]) if isinstance(values[f], str)
                else self._index(values[f], n, f"index of factor {f!r}")
                for f, n in zip(self.factors, self._sizes, strict=True)
            ]
        else:
            if isinstance(values, str | bytes) or not isinstance(values, Sequence | np.ndarray):
                raise TypeError(f"values must be a mapping or a sequence of int; got {values!r}")
            if len(values) != len(self._sizes):
                raise ValueError(
                    f"values must have one index per factor {self.factor_names}; "
                    f"got {len(values)}: {values!r}"
                )
            indices = [
                self._index(v, n, f"index of factor {f!r}")
                for v, f, n in zip(values, self.factors, self._sizes, strict=True)
            ]
        return sum(i * st for i, st in zip(indices, self._strides, strict=True))

    def decode(self, s: int) -> dict[str, int]:
        """Factor name -> value index of state ``s``, in factor order."""
        s = self._index(s, self.n_states, "state index")
        return {
            f: (s // st) % n
            for f, st, n in zip(self.factors, self._strides, self._sizes, strict=True)
        }

    def encode_array(self, indices: np.ndarray) -> np.ndarray:
        """Vectorised :meth:`encode`.

        Parameters
        ----------
        indices : array_like of int, shape (..., F)
            Value indices, the last axis in factor order.

        Returns
        -------
        ndarray of int64, shape (...)
        """
        idx = np.asarray(indices)
        if idx.ndim == 0 or idx.shape[-1] != len(self._sizes):
            raise ValueError(
                f"indices must have shape (..., F) = (..., {len(self._sizes)}); got {idx.shape}"
            )
        if idx.size and not np.issubdtype(idx.dtype, np.integer):
            raise TypeError(f"indices must be integers; got dtype {idx.dtype}")
        idx = idx.astype(np.int64)
        sizes = np.array(self._sizes)
        bad = (idx < 0) | (idx >= sizes)
        if bad.any():
            where = np.argwhere(bad)[0]
            f = int(where[-1])
            raise ValueError(
                f"index of factor {self.factor_names[f]!r} must be in [0, {self._sizes[f]}); "
                f"got {int(idx[tuple(where)])} at {tuple(int(w) for w in where)}"
            )
        return idx @ np.array(self._strides, dtype=np.int64)

    def decode_array(self, states: np.ndarray) -> np.ndarray:
        """Vectorised :meth:`decode`.

        Parameters
        ----------
        states : array_like of int, shape (...)

        Returns
        -------
        ndarray of int64, shape (..., F)
            Value indices, the last axis in factor order.
        """
        s = np.asarray(states)
        if s.size and not np.issubdtype(s.dtype, np.integer):
            raise TypeError(f"states must be integers; got dtype {s.dtype}")
        s = s.astype(np.int64)
        bad = (s < 0) | (s >= self.n_states)
        if bad.any():
            raise ValueError(
                f"state index must be in [0, {self.n_states}); got {int(s[bad][0])}"
            )
        return np.stack(np.unravel_index(s, self._sizes), axis=-1).astype(np.int64)

    # -- pair observations --------------------------------------------------------------------

    def pair(self, s: int, a: int) -> int:
        """The pair-observation index ``s * n_actions + a`` of state ``s`` and action ``a``.

        This is the observation index of :func:`irl.observation.pair_observation_model` and
        :meth:`irl.Demonstration.from_pairs`.
        """
        s = self._index(s, self.n_states, "state index")
        a = self._index(a, self.n_actions, "action index")
        return s * self.n_actions + a

    def unpair(self, o: int) -> tuple[int, int]:
        """The ``(s, a)`` of pair-observation index ``o``; inverse of :meth:`pair`."""
        o = self._index(o, self.n_pairs, "pair index")
        s, a = divmod(o, self.n_actions)
        return s, a

    # -- JSON ---------------------------------------------------------------------------------

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-ready data; factors as an ordered list of ``{"name", "values"}``."""
        return {
            "name": self.name,
            "factors": [{"name": f, "values": list(v)} for f, v in self.factors.items()],
            "action_names": list(self.action_names),
            "feature_names": list(self.feature_names),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> TaskDescription:
        """Inverse of :meth:`to_dict`; ``factors`` may also be a JSON object (ordered)."""
        if not isinstance(data, Mapping):
            raise TypeError(f"data must be a mapping; got {type(data).__name__}")
        missing = [k for k in _DICT_KEYS if k not in data]
        unknown = sorted(set(data) - set(_DICT_KEYS))
        if missing or unknown:
            raise ValueError(
                f"data must have exactly the keys {_DICT_KEYS}; missing {missing}, "
                f"unknown {unknown}"
            )
        return cls(
            name=data["name"],
            factors=data["factors"],
            action_names=data["action_names"],
            feature_names=data["feature_names"],
        )

    # -- helpers ------------------------------------------------------------------------------

    def _factor(self, factor: str) -> tuple[str, ...]:
        if factor not in self.factors:
            raise ValueError(f"factor must be one of {self.factor_names}; got {factor!r}")
        return self.factors[factor]

    @staticmethod
    def _index(value: Any, n: int, what: str) -> int:
        if isinstance(value, bool) or not isinstance(value, int | np.integer):
            raise TypeError(f"{what} must be an int; got {type(value).__name__} {value!r}")
        if not 0 <= value < n:
            raise ValueError(f"{what} must be in [0, {n}); got {value}")
        return int(value)
