"""Observation models ``O[s, a, o] = P(o | s, a)`` and the helpers that build them.

Layout: ``O[s, a, o]``; every ``O[s, a, :]`` sums to 1. An occluded step has no observation
and contributes a factor of 1 (it is not an observation of its own).

Observations that report a state-action pair use the index ``o = s * A + a``; observations
that report a state only use ``o = s``. States of a factored domain are indexed in row-major
(mixed-radix) order of their factors, the order ``np.ravel_multi_index`` uses.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cached_property, reduce

import numpy as np

from irl._validation import (
    as_float_array,
    check_int,
    check_probability_rows,
    describe,
)

__all__ = [
    "ObservationModel",
    "check_compatible",
    "factored_observation_model",
    "identity_observation_model",
    "pair_observation_model",
    "state_observation_model",
]


class ObservationModel:
    """A discrete observation model ``O[s, a, o] = P(o | s, a)``.

    Parameters
    ----------
    probs : ndarray of shape (S, A, n_observations)
        Non-negative, each ``probs[s, a, :]`` sums to 1.
    nominal : ndarray of shape (n_observations, 2), optional
        The ``(s, a)`` each observation reports at face value, with ``a = -1`` for
        observations that report no action. Baselines that take observations as exact
        (MAP-BIRL, MaxEnt) use it. Defaults to the maximum-likelihood pair
        ``argmax_{s, a} O[s, a, o]``.
    observation_names : sequence of str, optional
    """

    def __init__(
        self,
        probs: np.ndarray,
        *,
        nominal: np.ndarray | None = None,
        observation_names: Sequence[str] | None = None,
    ) -> None:
        probs = as_float_array(probs, "probs")
        if probs.ndim != 3 or min(probs.shape) < 1:
            raise ValueError(
                f"probs must have shape (S, A, n_observations), each at least 1; got "
                f"{probs.ndim} dimensions {probs.shape}"
            )
        check_probability_rows(probs, "observation model probs")
        self.probs = probs
        n_states, n_actions, n_obs = probs.shape
        if nominal is None:
            flat = probs.reshape(n_states * n_actions, n_obs).argmax(axis=0)
            nominal = np.stack(np.divmod(flat, n_actions), axis=1)
        if isinstance(nominal, (str, bytes, dict, set)):
            raise TypeError(f"nominal must be an integer array ({n_obs}, 2); got "
                            f"{describe(nominal)}")
        try:
            nominal = np.asarray(nominal)
        except ValueError as exc:  # ragged
            raise ValueError(f"nominal must have shape ({n_obs}, 2); got {exc}") from None
        if nominal.dtype == bool or not np.issubdtype(nominal.dtype, np.integer):
            raise TypeError(f"nominal must be an integer array ({n_obs}, 2); got dtype "
                            f"{nominal.dtype}")
        nominal = nominal.astype(np.int64)
        if nominal.shape != (n_obs, 2):
            raise ValueError(f"nominal must have shape ({n_obs}, 2); got {nominal.shape}")
        for col, what, low, high in ((0, "states", 0, n_states), (1, "actions", -1, n_actions)):
            bad = np.flatnonzero((nominal[:, col] < low) | (nominal[:, col] >= high))
            if bad.size:
                o = int(bad[0])
                raise ValueError(
                    f"nominal {what} must lie in [{low}, {high}); got nominal[{o}, {col}] = "
                    f"{nominal[o, col]} ({bad.size} out of range)"
                )
        self.nominal = nominal
        if observation_names is not None and (
            isinstance(observation_names, (str, bytes))
            or not isinstance(observation_names, Sequence | np.ndarray)
        ):
            raise TypeError(f"observation_names must be a sequence of {n_obs} str; got "
                            f"{describe(observation_names)}")
        if observation_names is not None and len(observation_names) != n_obs:
            raise ValueError(
                f"observation_names must have {n_obs} entries; got {len(observation_names)}"
            )
        self.observation_names = (
            [str(x) for x in observation_names] if observation_names is not None else None
        )

    @property
    def n_states(self) -> int:
        return self.probs.shape[0]

    @property
    def n_actions(self) -> int:
        return self.probs.shape[1]

    @property
    def n_observations(self) -> int:
        return self.probs.shape[2]

    @cached_property
    def emissions(self) -> np.ndarray:
        """``E[o, s, a] = O(o | s, a)`` with an extra last row of ones, shape (n_obs + 1, S, A).

        Observation-major, so one step's emissions are contiguous; indexing it with observation
        arrays whose occluded entries are ``-1`` gives a factor of 1 at occluded steps. Computed
        once per model.
        """
        table = np.ones((self.n_observations + 1, self.n_states, self.n_actions))
        table[:-1] = np.moveaxis(self.probs, 2, 0)
        return table

    @cached_property
    def log_emissions(self) -> np.ndarray:
        """``log E[o, s, a]`` (``-inf`` where ``O(o | s, a) = 0``; the last row is 0)."""
        table = np.full(self.emissions.shape, -np.inf)
        positive = self.emissions > 0
        table[positive] = np.log(self.emissions[positive])
        return table

    def error_rate(self, weights: np.ndarray | None = None) -> float:
        """Probability that the observation differs from the nominal report of the truth.

        Averaged over ``(s, a)`` with ``weights[s, a]`` (uniform by default); only defined for
        pair observations (``o = s * A + a``).
        """
        S, A = self.n_states, self.n_actions
        if self.n_observations != S * A:
            raise ValueError(
                f"error_rate needs pair observations (n_observations = S * A = {S * A}); "
                f"got {self.n_observations}"
            )
        correct = self.probs.reshape(S * A, S * A).diagonal().reshape(S, A)
        if weights is None:
            w = np.full((S, A), 1.0 / (S * A))
        else:
            w = as_float_array(weights, "weights")
            if w.shape != (S, A) or w.min() < 0 or not w.sum() > 0:
                raise ValueError(
                    f"weights must be non-negative of shape (S, A) = ({S}, {A}) with a positive "
                    f"sum; got shape {w.shape}"
                )
            w = w / w.sum()
        return float(1.0 - (w * correct).sum())

    def __repr__(self) -> str:
        return (
            f"ObservationModel(n_states={self.n_states}, n_actions={self.n_actions}, "
            f"n_observations={self.n_observations})"
        )


def check_compatible(mdp, observation_model) -> None:
    """Raise ``ValueError`` unless the observation model was built for this MDP's (S, A)."""
    from irl.mdp import TabularMDP

    if not isinstance(mdp, TabularMDP):
        raise TypeError(f"mdp must be an irl.TabularMDP; got {type(mdp).__name__}")
    if not isinstance(observation_model, ObservationModel):
        raise TypeError(
            "observation_model must be an irl.ObservationModel; got "
            f"{type(observation_model).__name__}"
        )
    got = (observation_model.n_states, observation_model.n_actions)
    want = (mdp.n_states, mdp.n_actions)
    if got != want:
        raise ValueError(
            f"observation_model is for (S, A) = {got} but mdp has (S, A) = {want}"
        )


def identity_observation_model(n_states: int, n_actions: int) -> ObservationModel:
    """Noise-free observation of the pair: ``o = s * A + a`` with probability 1.

    With this model and no occlusion, MMAP-BIRL is exactly MAP-BIRL.
    """
    n_states = check_int(n_states, "n_states", low=1)
    n_actions = check_int(n_actions, "n_actions", low=1)
    return pair_observation_model(np.eye(n_states), np.eye(n_actions))


def pair_observation_model(
    state_confusion: np.ndarray, action_confusion: np.ndarray | None = None, *, n_actions=None
) -> ObservationModel:
    """Observations of the pair ``(s', a')`` with independent state and action confusion.

    ``O[s, a, s' * A + a'] = C_S[s, s'] * C_A[a, a']``.

    Parameters
    ----------
    state_confusion : ndarray of shape (S, S)
        ``C_S[s, s'] = P(observed state s' | true state s)``.
    action_confusion : ndarray of shape (A, A), optional
        ``C_A[a, a']``; the identity (actions observed exactly) when omitted, in which case
        ``n_actions`` is required.
    """
    C_S = as_float_array(state_confusion, "state_confusion")
    if C_S.ndim != 2 or C_S.shape[0] != C_S.shape[1] or C_S.shape[0] < 1:
        raise ValueError(f"state_confusion must be square (S, S) with S >= 1; got {C_S.shape}")
    check_probability_rows(C_S, "state_confusion")
    if action_confusion is None:
        if n_actions is None:
            raise ValueError("give action_confusion or n_actions; got neither")
        C_A = np.eye(check_int(n_actions, "n_actions", low=1))
    else:
        C_A = as_float_array(action_confusion, "action_confusion")
        if C_A.ndim != 2 or C_A.shape[0] != C_A.shape[1] or C_A.shape[0] < 1:
            raise ValueError(f"action_confusion must be square (A, A); got {C_A.shape}")
        check_probability_rows(C_A, "action_confusion")
    S, A = C_S.shape[0], C_A.shape[0]
    probs = np.einsum("st,ab->satb", C_S, C_A).reshape(S, A, S * A)
    nominal = np.stack(np.divmod(np.arange(S * A), A), axis=1)
    return ObservationModel(probs, nominal=nominal)


def state_observation_model(state_confusion: np.ndarray, n_actions: int) -> ObservationModel:
    """Observations of the state only: ``O[s, a, s'] = C_S[s, s']`` for every action."""
    C_S = as_float_array(state_confusion, "state_confusion")
    if C_S.ndim != 2 or min(C_S.shape) < 1:
        raise ValueError(f"state_confusion must have shape (S, n_observations); got {C_S.shape}")
    check_probability_rows(C_S, "state_confusion")
    n_actions = check_int(n_actions, "n_actions", low=1)
    probs = np.repeat(C_S[:, None, :], n_actions, axis=1)
    nominal = None
    if C_S.shape[0] == C_S.shape[1]:
        nominal = np.stack([np.arange(C_S.shape[0]), np.full(C_S.shape[0], -1)], axis=1)
    return ObservationModel(probs, nominal=nominal)


def factored_observation_model(
    factor_confusions: Sequence[np.ndarray], action_confusion: np.ndarray | None = None,
    *, n_actions: int | None = None,
) -> ObservationModel:
    """Pair observations from independent per-factor confusion matrices.

    The state is factored as ``s = ravel_multi_index((f_1, ..., f_F), sizes)``; each factor is
    observed through its own confusion matrix ``C_f[true, observed]``, so the state confusion is
    their Kronecker product. This is what perception calibration measures.
    """
    if isinstance(factor_confusions, (str, bytes, np.ndarray)) or not isinstance(
        factor_confusions, Sequence
    ):
        raise TypeError(
            "factor_confusions must be a sequence of square matrices; got "
            f"{describe(factor_confusions)}"
        )
    mats = [as_float_array(c, f"factor_confusions[{i}]") for i, c in enumerate(factor_confusions)]
    if not mats:
        raise ValueError("factor_confusions must hold at least one matrix; got none")
    for i, c in enumerate(mats):
        if c.ndim != 2 or c.shape[0] != c.shape[1] or c.shape[0] < 1:
            raise ValueError(f"factor_confusions[{i}] must be square; got {c.shape}")
        check_probability_rows(c, f"factor_confusions[{i}]")
    return pair_observation_model(reduce(np.kron, mats), action_confusion, n_actions=n_actions)
