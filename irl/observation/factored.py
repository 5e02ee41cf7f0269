"""Pair observations through independent per-factor confusion matrices, never a dense O.

Layout: the state is ``s = ravel_multi_index((f_1, ..., f_F), sizes)`` (row-major); each factor
is observed through ``C_f[true, observed]``, the action through ``C_A[a, a']``, and the
observation is the pair ``o = s' * A + a'``, so

    O[s, a, s' * A + a'] = C_A[a, a'] * prod_f C_f[s_f, s'_f]

(the Kronecker product of the factors' confusions, what perception calibration measures). The
likelihood of one observation over all ``S A`` pairs is a sum of ``F + 1`` broadcast columns in
log space: ``O(S A)`` work and memory per observation, against ``O(S^2 A^2)`` for the dense array.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cached_property, reduce

import numpy as np

from irl._validation import as_float_array, check_int, check_probability_rows, describe
from irl.observation.base import ObservationModel, check_names, safe_log

__all__ = ["FactoredObservationModel"]


def _square_confusion(c, name: str) -> np.ndarray:
    c = as_float_array(c, name)
    if c.ndim != 2 or c.shape[0] != c.shape[1] or c.shape[0] < 1:
        raise ValueError(f"{name} must be square; got {c.shape}")
    check_probability_rows(c, name)
    return c


class FactoredObservationModel(ObservationModel):
    """``O[s, a, s' * A + a'] = C_A[a, a'] prod_f C_f[s_f, s'_f]`` from its factors.

    Parameters
    ----------
    factor_confusions : sequence of ndarray, each of shape (n_f, n_f)
        ``C_f[true, observed]`` of each state factor, in the order of the state's row-major
        encoding; ``S = prod_f n_f``.
    action_confusion : ndarray of shape (A, A), optional
        ``C_A[a, a']``; the identity (actions observed exactly) when omitted, in which case
        ``n_actions`` is required.
    n_actions : int, optional
        ``A`` when ``action_confusion`` is omitted.
    observation_names : sequence of str, optional

    Attributes
    ----------
    factor_confusions : list of ndarray
        ``C_f`` of each state factor, validated.
    action_confusion : ndarray of shape (A, A)
        ``C_A`` (the identity when none was given).
    sizes : tuple of int
        ``n_f`` of each factor.
    n_states, n_actions, n_observations : int
        ``S``, ``A`` and the number of observations.
    nominal : ndarray of int, shape (n_observations, 2)
        The ``(s, a)`` each observation reports at face value (``a = -1``: no action).
    observation_names : list of str or None

    Notes
    -----
    ``nominal[o]`` is the pair ``divmod(o, A)`` the observation reports.
    """

    def __init__(
        self,
        factor_confusions: Sequence[np.ndarray],
        action_confusion: np.ndarray | None = None,
        *,
        n_actions: int | None = None,
        observation_names: Sequence[str] | None = None,
    ) -> None:
        if isinstance(factor_confusions, (str, bytes, np.ndarray)) or not isinstance(
            factor_confusions, Sequence
        ):
            raise TypeError(
                "factor_confusions must be a sequence of square matrices; got "
                f"{describe(factor_confusions)}"
            )
        mats = [_square_confusion(c, f"factor_confusions[{i}]")
                for i, c in enumerate(factor_confusions)]
        if not mats:
            raise ValueError("factor_confusions must hold at least one matrix; got none")
        if action_confusion is None:
            if n_actions is None:
                raise ValueError("give action_confusion or n_actions; got neither")
            action = np.eye(check_int(n_actions, "n_actions", low=1))
        else:
            action = _square_confusion(action_confusion, "action_confusion")
            if n_actions is not None and check_int(n_actions, "n_actions", low=1) != len(action):
                raise ValueError(f"n_actions must equal action_confusion's {len(action)}; got "
                                 f"{n_actions}")
        self.factor_confusions = mats
        self.action_confusion = action
        self.sizes = tuple(len(c) for c in mats)
        self.n_states = int(np.prod(self.sizes))
        self.n_actions = len(action)
        self.n_observations = self.n_states * self.n_actions
        self.observation_names = check_names(observation_names, self.n_observations)
        self._log_factors = [safe_log(c) for c in mats]
        self._log_action = safe_log(action)

    @cached_property
    def nominal(self) -> np.ndarray:
        return np.stack(np.divmod(np.arange(self.n_observations), self.n_actions), axis=1)

    def _log_likelihoods(self, obs: np.ndarray) -> np.ndarray:
        m = obs.size
        seen_state, seen_action = np.divmod(obs, self.n_actions)
        parts = np.unravel_index(seen_state, self.sizes)
        total = np.zeros((m, *self.sizes))
        n_f = len(self.sizes)
        for f, (log_c, part) in enumerate(zip(self._log_factors, parts, strict=True)):
            shape = [m] + [1] * n_f
            shape[1 + f] = self.sizes[f]
            total += log_c[:, part].T.reshape(shape)
        out = np.empty((m, self.n_states, self.n_actions))
        np.add(total.reshape(m, self.n_states, 1),
               self._log_action[:, seen_action].T[:, None, :], out=out)
        return out

    def separable_likelihoods(self, obs):
        """As :meth:`ObservationModel.separable_likelihoods`: the state part is the product of
        the factors' columns, the action part the action confusion's column, each divided by
        its maximum (the shift is the sum of their log-maxima)."""
        head, tail, action, shift, min_log = self.kronecker_likelihoods(obs)
        obs_shape = shift.shape
        m = shift.size
        state = (head.reshape(m, -1)[:, :, None] * tail.reshape(m, -1)[:, None, :])
        return state.reshape((*obs_shape, self.n_states)), action, shift, min_log

    def kronecker_likelihoods(self, obs):
        """As :meth:`ObservationModel.kronecker_likelihoods`: ``head`` is the product of the
        columns of every factor but the last (ones of one column for a single factor),
        ``tail`` the last factor's column, so that ``head[..., i] * tail[..., j]`` is the state
        part :meth:`separable_likelihoods` returns at ``s = i * n_last + j``, bit for bit."""
        obs = np.asarray(obs)
        flat = obs.reshape(-1)
        m = flat.size
        occluded = flat < 0
        seen_state, seen_action = np.divmod(np.where(occluded, 0, flat), self.n_actions)
        parts = [*np.unravel_index(seen_state, self.sizes), seen_action]
        columns = []
        shift = np.zeros(m)
        low = np.zeros(m)
        with np.errstate(invalid="ignore"):
            for (scaled, log_top, log_low), part in zip(self._scaled_columns, parts,
                                                        strict=True):
                col = scaled[part]  # (m, n_f), a fresh array
                col[occluded] = 1.0
                columns.append(col)
                shift += log_top[part]
                low += log_low[part]
        shift[occluded] = 0.0
        low[occluded] = 0.0
        possible = np.isfinite(shift)
        min_log = float(low[possible].min()) if possible.any() else 0.0
        if len(columns) == 2:  # one factor: the state part is its column, times 1.0
            head = np.ones((m, 1))
        else:
            head = columns[0]
            for col in columns[1:-2]:
                head = (head[:, :, None] * col[:, None, :]).reshape(m, -1)
        tail = columns[-2]
        return (head.reshape((*obs.shape, -1)), tail.reshape((*obs.shape, -1)),
                columns[-1].reshape((*obs.shape, self.n_actions)), shift.reshape(obs.shape),
                min_log)

    @cached_property
    def _scaled_columns(self) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Per confusion (the factors', then the action's), what a seen value selects:
        ``(scaled[observed, true], log_top[observed], log_low[observed])``, its columns
        divided by their maxima, the log of each maximum, and the log of each scaled column's
        smallest positive entry (``-inf``, ``nan`` and ``inf`` where a column is all zeros: an
        impossible observation, as its shift says)."""
        out = []
        with np.errstate(divide="ignore", invalid="ignore"):
            for c in [*self.factor_confusions, self.action_confusion]:
                top = c.max(axis=0)
                scaled = np.ascontiguousarray((c / top).T)
                out.append((scaled, np.log(top),
                            np.log(np.where(scaled > 0, scaled, np.inf).min(axis=1))))
        return out

    def scaled_likelihoods(self, obs, *, action_major: bool = False
                           ) -> tuple[np.ndarray, np.ndarray, float]:
        """As :meth:`ObservationModel.scaled_likelihoods`: the outer product of
        :meth:`separable_likelihoods` (one pass over the ``S A`` pairs per observation)."""
        state, action, shift, min_log = self.separable_likelihoods(obs)
        if action_major:  # the long axis innermost: a fast broadcast
            factor = action[..., :, None] * state[..., None, :]
        else:
            factor = state[..., :, None] * action[..., None, :]
        return factor, shift, min_log

    def distribution(self, state: int, action: int) -> np.ndarray:
        parts = np.unravel_index(state, self.sizes)
        rows = [c[p] for c, p in zip(self.factor_confusions, parts, strict=True)]
        return reduce(np.kron, [*rows, self.action_confusion[action]])

    @cached_property
    def state_confusion(self) -> np.ndarray:
        """The dense ``C_S = C_1 kron ... kron C_F``, shape (S, S); for small models."""
        return reduce(np.kron, self.factor_confusions)

    @cached_property
    def probs(self) -> np.ndarray:
        S, A = self.n_states, self.n_actions
        return np.einsum("st,ab->satb", self.state_confusion,
                         self.action_confusion).reshape(S, A, S * A)

    def _correct(self) -> np.ndarray:
        diag = reduce(np.kron, [np.diagonal(c) for c in self.factor_confusions])
        return np.outer(diag, np.diagonal(self.action_confusion))
