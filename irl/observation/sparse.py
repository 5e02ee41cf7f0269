"""Observation models stored as sparse matrices, and state-only observations.

Layouts: the sparse model holds ``M[s * A + a, o] = O(o | s, a)`` (CSC, so an observation's
likelihoods over all pairs are one column); the state-only model holds ``C[s, o]`` and
``O[s, a, o] = C[s, o]`` for every action. A zero is an observation the pair cannot emit
(log-likelihood ``-inf``). Work and memory per observation are ``O(S A)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from irl._validation import as_float_array, check_int, check_probability_rows, describe
from irl.observation.base import ObservationModel, check_names, check_nominal, safe_log

__all__ = ["SparseObservationModel", "StateObservationModel"]


def _as_csc(matrix, name: str) -> sp.csc_matrix:
    """A 2-D sparse or dense matrix as a CSC matrix with positive entries only, or raise."""
    if sp.issparse(matrix):
        if matrix.ndim != 2:
            raise ValueError(f"{name} must be 2-D; got shape {matrix.shape}")
        csc = sp.csc_matrix(matrix, dtype=float)
    else:
        csc = sp.csc_matrix(as_float_array(matrix, name, ndim=2))
    if min(csc.shape) < 1:
        raise ValueError(f"{name} must have at least one row and column; got {csc.shape}")
    check_probability_rows(csc, name)
    csc.sum_duplicates()
    csc.eliminate_zeros()
    csc.sort_indices()
    return csc


def _log_columns(csc: sp.csc_matrix, log_data: np.ndarray, obs: np.ndarray) -> np.ndarray:
    """``log csc[:, obs[m]]`` as a dense (M, n_rows) array, ``-inf`` off the pattern."""
    m = obs.size
    out = np.full((m, csc.shape[0]), -np.inf)
    starts = csc.indptr[obs]
    lengths = csc.indptr[obs + 1] - starts
    ends = np.cumsum(lengths)
    pos = np.repeat(starts - (ends - lengths), lengths) + np.arange(ends[-1] if m else 0)
    out[np.repeat(np.arange(m), lengths), csc.indices[pos]] = log_data[pos]
    return out


class SparseObservationModel(ObservationModel):
    """``O(o | s, a)`` as a sparse matrix ``M[s * A + a, o]`` (each row sums to 1).

    Parameters
    ----------
    matrix : scipy.sparse matrix or ndarray of shape (S * A, n_observations)
        Row ``s * A + a`` is ``O[s, a, :]``.
    n_actions : int
    nominal : ndarray of shape (n_observations, 2), optional
        Defaults to the maximum-likelihood pair of each observation.
    observation_names : sequence of str, optional

    Attributes
    ----------
    matrix : scipy.sparse.csc_matrix of shape (S * A, n_observations)
        ``M``, its explicit zeros dropped.
    n_states, n_actions, n_observations : int
        ``S``, ``A`` and the number of observations.
    nominal : ndarray of int, shape (n_observations, 2)
        The ``(s, a)`` each observation reports at face value (``a = -1``: no action).
    observation_names : list of str or None
    """

    def __init__(self, matrix, n_actions: int, *, nominal: np.ndarray | None = None,
                 observation_names: Sequence[str] | None = None) -> None:
        if matrix is None or isinstance(matrix, (str, bytes, dict, set)):
            raise TypeError(f"matrix must be a sparse or dense (S * A, n_observations) matrix; "
                            f"got {describe(matrix)}")
        n_actions = check_int(n_actions, "n_actions", low=1)
        csc = _as_csc(matrix, "matrix")
        rows, self.n_observations = csc.shape
        if rows % n_actions:
            raise ValueError(f"matrix must have S * A rows with A = n_actions = {n_actions}; got "
                             f"{rows} rows")
        self.n_actions = n_actions
        self.n_states = rows // n_actions
        self.matrix = csc
        self._log_data = np.log(csc.data)
        if nominal is not None:
            self.nominal = check_nominal(nominal, self.n_observations, self.n_states, n_actions)
        self.observation_names = check_names(observation_names, self.n_observations)

    @cached_property
    def nominal(self) -> np.ndarray:
        best = np.asarray(self.matrix.argmax(axis=0)).ravel()
        return np.stack(np.divmod(best, self.n_actions), axis=1)

    def _log_likelihoods(self, obs: np.ndarray) -> np.ndarray:
        out = _log_columns(self.matrix, self._log_data, obs)
        return out.reshape(obs.size, self.n_states, self.n_actions)

    def distribution(self, state: int, action: int) -> np.ndarray:
        row = self.matrix[state * self.n_actions + action]
        return row.toarray().ravel()


class StateObservationModel(ObservationModel):
    """Observations of the state only: ``O[s, a, o] = C[s, o]`` for every action.

    Parameters
    ----------
    state_confusion : ndarray or scipy.sparse matrix of shape (S, n_observations)
        ``C[s, o] = P(o | s)``; each row sums to 1.
    n_actions : int
    nominal : ndarray of shape (n_observations, 2), optional
        Defaults to ``(o, -1)`` (the state ``o``, no action) when C is square, else to
        ``(argmax_s C[s, o], 0)``.
    observation_names : sequence of str, optional

    Attributes
    ----------
    n_states, n_actions, n_observations : int
        ``S``, ``A`` and the number of observations.
    nominal : ndarray of int, shape (n_observations, 2)
        The ``(s, a)`` each observation reports at face value (``a = -1``: no action).
    observation_names : list of str or None
    """

    def __init__(self, state_confusion, n_actions: int, *, nominal: np.ndarray | None = None,
                 observation_names: Sequence[str] | None = None) -> None:
        if state_confusion is None or isinstance(state_confusion, (str, bytes, dict, set)):
            raise TypeError(f"state_confusion must be an (S, n_observations) matrix; got "
                            f"{describe(state_confusion)}")
        self.n_actions = check_int(n_actions, "n_actions", low=1)
        if sp.issparse(state_confusion):
            self._csc = _as_csc(state_confusion, "state_confusion")
            self._log_data = np.log(self._csc.data)
            self._by_obs = None
            self.n_states, self.n_observations = self._csc.shape
        else:
            C = as_float_array(state_confusion, "state_confusion")
            if C.ndim != 2 or min(C.shape) < 1:
                raise ValueError(f"state_confusion must have shape (S, n_observations); got "
                                 f"{C.shape}")
            check_probability_rows(C, "state_confusion")
            self._csc = None
            self._by_obs = np.ascontiguousarray(C.T)  # C[s, o] observation-major
            self.n_states, self.n_observations = C.shape
        if nominal is not None:
            self.nominal = check_nominal(nominal, self.n_observations, self.n_states,
                                         self.n_actions)
        self.observation_names = check_names(observation_names, self.n_observations)

    @cached_property
    def nominal(self) -> np.ndarray:
        n_obs = self.n_observations
        if self.n_states == n_obs:
            return np.stack([np.arange(n_obs), np.full(n_obs, -1)], axis=1)
        if self._csc is not None:
            best = np.asarray(self._csc.argmax(axis=0)).ravel()
        else:
            best = self._by_obs.argmax(axis=1)
        return np.stack([best, np.zeros(n_obs, np.int64)], axis=1)

    @cached_property
    def _log_by_obs(self) -> np.ndarray:
        """``log C[s, o]`` observation-major (dense C), taken once: the log-space pass reads
        one row per demonstration and step, twice."""
        return safe_log(self._by_obs)

    def _log_state(self, obs: np.ndarray) -> np.ndarray:
        if self._csc is not None:
            return _log_columns(self._csc, self._log_data, obs)
        return self._log_by_obs[obs]

    def _log_likelihoods(self, obs: np.ndarray) -> np.ndarray:
        out = np.empty((obs.size, self.n_states, self.n_actions))
        out[...] = self._log_state(obs)[:, :, None]
        return out

    def separable_likelihoods(self, obs):
        """As :meth:`ObservationModel.separable_likelihoods`: the state part is the column
        ``C[:, o]`` divided by its maximum, the action part ones (dense C; None for a sparse
        one, whose columns the generic path gathers)."""
        if self._csc is not None:
            return None
        obs = np.asarray(obs)
        flat = obs.reshape(-1)
        seen = np.flatnonzero(flat >= 0)
        cols = np.ones((flat.size, self.n_states))
        shift = np.zeros(flat.size)
        min_log = 0.0
        if seen.size:
            c = self._by_obs[flat[seen]]
            top = c.max(axis=1)
            with np.errstate(divide="ignore", invalid="ignore"):
                c /= top[:, None]
                shift[seen] = np.log(top)
                low = np.log(np.where(c > 0, c, np.inf).min(axis=1))
            cols[seen] = c
            possible = top > 0
            if possible.any():
                min_log = float(low[possible].min())
        return (cols.reshape((*obs.shape, self.n_states)),
                np.ones((*obs.shape, self.n_actions)), shift.reshape(obs.shape), min_log)

    def scaled_likelihoods(self, obs, *, action_major: bool = False
                           ) -> tuple[np.ndarray, np.ndarray, float]:
        """As :meth:`ObservationModel.scaled_likelihoods`: each column ``C[:, o]`` divided by
        its maximum, repeated over the actions."""
        if self._csc is not None:
            return super().scaled_likelihoods(obs, action_major=action_major)
        cols, _, shift, min_log = self.separable_likelihoods(obs)
        tail = (self.n_actions, self.n_states) if action_major else (self.n_states,
                                                                      self.n_actions)
        factor = np.empty((*cols.shape[:-1], *tail))
        factor[...] = cols[..., None, :] if action_major else cols[..., :, None]
        return factor, shift, min_log

    def distribution(self, state: int, action: int) -> np.ndarray:
        if self._csc is not None:
            return self._csc[state].toarray().ravel()
        return self._by_obs[:, state].copy()
