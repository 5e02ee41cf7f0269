"""The dense observation model: the whole array ``O[s, a, o]`` in memory.

Layout: ``O[s, a, o]``; the emission tables are observation-major, ``E[o, s, a]``.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cached_property

import numpy as np

from irl._validation import as_float_array, check_probability_rows
from irl.observation.base import ObservationModel, check_names, check_nominal, safe_log

__all__ = ["DenseObservationModel"]


class DenseObservationModel(ObservationModel, default=True):
    """``O[s, a, o] = P(o | s, a)`` stored as one array (what ``ObservationModel(probs)`` builds).

    Parameters
    ----------
    probs : ndarray of shape (S, A, n_observations)
        Non-negative, each ``probs[s, a, :]`` sums to 1.
    nominal : ndarray of shape (n_observations, 2), optional
        The ``(s, a)`` each observation reports at face value, with ``a = -1`` for
        observations that report no action. Defaults to the maximum-likelihood pair
        ``argmax_{s, a} O[s, a, o]``.
    observation_names : sequence of str, optional

    Attributes
    ----------
    probs : ndarray of shape (S, A, n_observations)
        ``O`` as given (validated).
    n_states, n_actions, n_observations : int
        ``S``, ``A`` and the number of observations.
    nominal : ndarray of int, shape (n_observations, 2)
        The ``(s, a)`` each observation reports at face value (``a = -1``: no action).
    observation_names : list of str or None
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
        self.n_states, self.n_actions, self.n_observations = probs.shape
        if nominal is not None:
            self.nominal = check_nominal(nominal, self.n_observations, self.n_states,
                                         self.n_actions)
        else:
            _ = self.nominal  # the default, computed now from the array we hold
        self.observation_names = check_names(observation_names, self.n_observations)

    @cached_property
    def log_emissions(self) -> np.ndarray:
        """``log E[o, s, a]`` (``-inf`` where ``O(o | s, a) = 0``; the last row is 0).

        Observation-major, so one step's emissions are contiguous and indexing with an
        observation array whose occluded entries are ``-1`` gives zeros there.
        """
        table = np.zeros((self.n_observations + 1, self.n_states, self.n_actions))
        table[:-1] = safe_log(np.moveaxis(self.probs, 2, 0))
        return table

    @cached_property
    def _scaled_table(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per observation (and a last occluded row): the action-major factor
        ``O[:, :, o].T / max``, its log-shift and the log of its smallest positive entry."""
        ll = self.log_emissions
        shift = ll.max(axis=(1, 2))
        with np.errstate(invalid="ignore"):
            shifted = ll - shift[:, None, None]
        low = np.where(np.isfinite(shifted), shifted, 0.0).min(axis=(1, 2))
        factor = np.ascontiguousarray(np.swapaxes(np.exp(shifted), 1, 2))
        return factor, shift, low

    def scaled_likelihoods(self, obs, *, action_major: bool = False
                           ) -> tuple[np.ndarray, np.ndarray, float]:
        """As :meth:`ObservationModel.scaled_likelihoods`, gathered from a table computed
        once per model."""
        if not action_major:
            return super().scaled_likelihoods(obs)
        obs = np.asarray(obs)
        factor, shift, low = self._scaled_table
        shifts = shift[obs]
        possible = np.isfinite(shifts)
        min_log = float(low[obs][possible].min()) if possible.any() else 0.0
        return factor[obs], shifts, min_log

    def log_likelihoods(self, obs) -> np.ndarray:
        return self.log_emissions[np.asarray(obs)]

    def _log_likelihoods(self, obs: np.ndarray) -> np.ndarray:
        return self.log_emissions[obs]

    def distribution(self, state: int, action: int) -> np.ndarray:
        return self.probs[state, action]
