"""Tabular Markov decision processes with linear rewards.

Array layouts used throughout the project: ``T[s, a, s']``, ``phi[s, a, k]``, ``p0[s]``,
``R[s, a]``, ``Q[s, a]``, ``pi[s, a]``.

Transitions are given either densely as ``T[s, a, s']`` or as one ``scipy.sparse`` ``S x S``
matrix per action. Internally both become one *flat* operator ``P[s * A + a, s']`` (a dense
array or a CSR matrix), so every kernel is written once and never forms a dense ``S x S``
matrix for a sparse MDP.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp

from irl._validation import check_probability_rows

__all__ = ["TabularMDP"]


class TabularMDP:
    """A finite MDP whose reward is linear in features: ``R(s, a) = phi[s, a] . theta``.

    Parameters
    ----------
    transitions : ndarray of shape (S, A, S) or sequence of A sparse matrices of shape (S, S)
        ``T[s, a, s'] = P(s' | s, a)``; every row sums to 1.
    features : ndarray of shape (S, A, K)
        ``phi[s, a, k]``, the reward features.
    discount : float
        Discount factor gamma in [0, 1).
    initial : ndarray of shape (S,)
        Initial state distribution ``p0[s]``.
    state_names, action_names, feature_names : sequence of str, optional
        Human-readable names, used in reports and plots.
    """

    def __init__(
        self,
        *,
        transitions: np.ndarray | Sequence[sp.spmatrix],
        features: np.ndarray,
        discount: float,
        initial: np.ndarray,
        state_names: Sequence[str] | None = None,
        action_names: Sequence[str] | None = None,
        feature_names: Sequence[str] | None = None,
    ) -> None:
        self.transitions = transitions
        if sp.issparse(transitions) or (
            isinstance(transitions, Sequence) and not isinstance(transitions, np.ndarray)
        ):
            flat, n_states, n_actions = _flatten_sparse(transitions)
        else:
            flat, n_states, n_actions = _flatten_dense(transitions)
        self._flat = flat
        self.n_states = n_states
        self.n_actions = n_actions

        features = np.asarray(features, dtype=float)
        if features.ndim != 3 or features.shape[:2] != (n_states, n_actions):
            raise ValueError(
                f"features must have shape (S, A, K) = ({n_states}, {n_actions}, K) to match "
                f"transitions; got {features.shape}"
            )
        if not np.all(np.isfinite(features)):
            raise ValueError("features must be finite; got NaN or inf entries")
        self.features = features
        self.n_features = features.shape[2]

        discount = float(discount)
        if not 0.0 <= discount < 1.0:
            raise ValueError(f"discount must be in [0, 1); got {discount}")
        self.discount = discount

        initial = np.asarray(initial, dtype=float)
        if initial.shape != (n_states,):
            raise ValueError(f"initial must have shape (S,) = ({n_states},); got {initial.shape}")
        check_probability_rows(initial[None, :], "initial")
        self.initial = initial

        self.state_names = _names(state_names, n_states, "state_names", "s")
        self.action_names = _names(action_names, n_actions, "action_names", "a")
        self.feature_names = _names(feature_names, self.n_features, "feature_names", "phi")

    @property
    def is_sparse(self) -> bool:
        """True when transitions are stored as a sparse matrix."""
        return sp.issparse(self._flat)

    def reward(self, theta: np.ndarray) -> np.ndarray:
        """Reward table ``R[s, a] = phi[s, a] . theta`` of shape (S, A)."""
        return self.features @ self.check_theta(theta)

    def check_theta(self, theta: np.ndarray) -> np.ndarray:
        """Return ``theta`` as a float vector of length K, or raise ``ValueError``."""
        theta = np.asarray(theta, dtype=float)
        if theta.shape != (self.n_features,):
            raise ValueError(
                f"theta must have shape (K,) = ({self.n_features},); got {theta.shape}"
            )
        if not np.all(np.isfinite(theta)):
            raise ValueError(f"theta must be finite; got {theta}")
        return theta

    # -- flat-operator kernels (shared by the solvers and forward-backward) ------------------

    def expect_next(self, values: np.ndarray) -> np.ndarray:
        """``sum_s' T[s, a, s'] values[s', ...]``, shape (S, A, ...).

        ``values`` has shape (S,) or (S, m); the result keeps the trailing dimension.
        """
        out = self._flat @ values
        return np.asarray(out).reshape((self.n_states, self.n_actions, *values.shape[1:]))

    def push_forward(self, mass: np.ndarray) -> np.ndarray:
        """Next-state mass ``sum_{s, a} mass[..., s, a] T[s, a, s']``, shape (..., S)."""
        lead = mass.shape[:-2]
        flat_mass = mass.reshape(-1, self.n_states * self.n_actions)
        out = (self._flat.T @ flat_mass.T).T
        return np.asarray(out).reshape((*lead, self.n_states))

    def next_state_distribution(self, state: int, action: int) -> np.ndarray:
        """``T[state, action, :]`` as a dense vector of shape (S,)."""
        row = self._flat[state * self.n_actions + action]
        row = row.toarray().ravel() if sp.issparse(row) else np.array(row, dtype=float)
        return row / row.sum()

    def policy_transitions(self, policy: np.ndarray) -> np.ndarray | sp.csr_matrix:
        """``P_pi[s, s'] = T[s, policy[s], s']`` of a deterministic policy (sparse if T is)."""
        rows = np.arange(self.n_states) * self.n_actions + policy
        return self._flat[rows]

    def __repr__(self) -> str:
        kind = "sparse" if self.is_sparse else "dense"
        return (
            f"TabularMDP(n_states={self.n_states}, n_actions={self.n_actions}, "
            f"n_features={self.n_features}, discount={self.discount}, {kind})"
        )


def _flatten_dense(transitions: np.ndarray) -> tuple[np.ndarray, int, int]:
    T = np.asarray(transitions, dtype=float)
    if T.ndim != 3 or T.shape[0] != T.shape[2]:
        raise ValueError(f"transitions must have shape (S, A, S); got {T.shape}")
    n_states, n_actions = T.shape[:2]
    flat = np.ascontiguousarray(T.reshape(n_states * n_actions, n_states))
    check_probability_rows(flat, "transitions")
    return flat, n_states, n_actions


def _flatten_sparse(transitions) -> tuple[sp.csr_matrix, int, int]:
    if sp.issparse(transitions):
        raise TypeError(
            "transitions given as sparse must be a sequence of one (S, S) matrix per action; "
            f"got a single {type(transitions).__name__}"
        )
    mats = [sp.csr_matrix(m, dtype=float) for m in transitions]
    if not mats:
        raise ValueError("transitions must hold at least one action's matrix; got none")
    n_states = mats[0].shape[0]
    for a, m in enumerate(mats):
        if m.shape != (n_states, n_states):
            raise ValueError(
                f"transitions[{a}] must have shape (S, S) = ({n_states}, {n_states}); "
                f"got {m.shape}"
            )
    n_actions = len(mats)
    # Interleave rows so that row s * A + a is T[s, a, :].
    stacked = sp.vstack(mats, format="csr")  # row a * S + s
    order = (np.arange(n_states)[:, None] + np.arange(n_actions)[None, :] * n_states).ravel()
    flat = stacked[order].tocsr()
    flat.sum_duplicates()
    check_probability_rows(flat, "transitions")
    return flat, n_states, n_actions


def _names(names, n: int, argname: str, prefix: str) -> list[str]:
    if names is None:
        return [f"{prefix}{i}" for i in range(n)]
    names = [str(x) for x in names]
    if len(names) != n:
        raise ValueError(f"{argname} must have {n} entries; got {len(names)}")
    return names
