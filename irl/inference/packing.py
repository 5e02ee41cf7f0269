"""Demonstrations packed into batches for forward-backward, their observations as the passes
read them, and what a pass returns per demonstration.

Layouts: packed observations ``obs[n, t]`` (-1 = occluded or padding), lengths ``lengths[n]``,
shifted observation likelihoods ``factor[n, t, a, s]`` with their shifts ``shift[n, t]``
(:class:`ObservationFactors`), results ``occupancy[n, s, a]`` and ``initial[n, s]``.

Batching. All demonstrations of a batch go through one pass: at each step one sparse product
``T`` times the dense block ``(N, S A)`` of their messages replaces N matrix-vector products.
Demonstrations of different lengths share a batch padded to the longest of them; a padded step
contributes nothing (its normalizer is left out of the likelihood, its posterior out of the
occupancy, and the backward message restarts at 1 at each demonstration's last step), so the
result is the same as one pass per demonstration. A time-indexed policy (steps to go) needs
equal lengths per batch. For one fit the packing keeps the observations' shifted likelihoods,
since the observations do not change with theta.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from irl.demonstrations import Demonstration, check_demonstrations

#: Largest ``N T S A`` whose observation log-likelihoods a packing keeps for reuse (32 MB).
_CACHE_ELEMENTS = 1 << 22
#: Padding allowed in a batch of ragged demonstrations, as a fraction of its real steps.
_PAD_SLACK = 0.25


@dataclass(frozen=True)
class PosteriorStats:
    """Sufficient statistics of the posterior over hidden pairs, per demonstration.

    Attributes
    ----------
    log_likelihood : ndarray of shape (N,)
        ``log P(o_1..T)`` of each demonstration.
    occupancy : ndarray of shape (N, S, A)
        ``sum_t P(s_t = s, a_t = a | o)``: expected visits of each pair.
    initial : ndarray of shape (N, S)
        ``P(s_1 = s | o)``.
    """

    log_likelihood: np.ndarray
    occupancy: np.ndarray
    initial: np.ndarray


@dataclass(frozen=True, eq=False)
class ObservationFactors:
    """Observation likelihoods of a block of steps, shifted so that nothing under- or
    overflows: ``O(obs[n, t] | s, a) = exp(shift[n, t]) * factor[n, t, s, a]``.

    Attributes
    ----------
    factor : ndarray of shape (N, T, A, S)
        Action-major; at most 1, with maximum 1 over the pairs of every step.
    shift : ndarray of shape (N, T)
        ``max_{s, a} log O(obs[n, t] | s, a)`` (0 at occluded steps).
    min_log : float
        ``log`` of the smallest positive factor.
    possible : bool
        False when some step's observation has probability 0 under every pair (then
        ``factor`` and ``shift`` are None).
    """

    factor: np.ndarray | None
    shift: np.ndarray | None
    min_log: float
    possible: bool

    @cached_property
    def columns(self) -> np.ndarray:
        """``factor`` with the demonstrations innermost, ``[t, a, s, n]`` (the scaled pass's
        layout), formed on first use and kept."""
        return np.ascontiguousarray(np.moveaxis(self.factor, 0, -1))

    def steps(self, t0: int, t1: int) -> ObservationFactors:
        """The factors of steps t0..t1-1 (views)."""
        if not self.possible:
            return self
        return ObservationFactors(self.factor[:, t0:t1], self.shift[:, t0:t1], self.min_log,
                                  True)


def observation_factors(observation_model, obs: np.ndarray) -> ObservationFactors:
    """:class:`ObservationFactors` of observations ``obs[n, t]`` (-1: occluded), from
    :meth:`irl.observation.ObservationModel.scaled_likelihoods`.

    Parameters
    ----------
    observation_model : ObservationModel
    obs : ndarray of int, shape (N, T)

    Returns
    -------
    ObservationFactors
        ``possible`` False when some step's observation is impossible under every pair.
    """
    factor, shift, min_log = observation_model.scaled_likelihoods(obs, action_major=True)
    if not np.all(np.isfinite(shift)):
        return ObservationFactors(None, None, -np.inf, False)
    return ObservationFactors(factor, shift, min_log, True)


@dataclass(frozen=True, eq=False)
class PackedDemonstrations:
    """Demonstrations packed once for many forward-backward passes (e.g. one fit).

    Attributes
    ----------
    observation_model : ObservationModel
    batches : tuple of ndarray of int
        Indices of the demonstrations run together.
    obs : tuple of ndarray of int, each (n_b, T_b)
        Their observations, padded with -1 to the batch's longest.
    lengths : tuple of ndarray of int, each (n_b,)
    factors : tuple of (ObservationFactors or None)
        The shifted observation likelihoods of each batch, kept when the packing is small
        enough (``_CACHE_ELEMENTS``); otherwise computed per chunk of steps at every pass.
    n_demos : int
    equal_lengths : bool
        Whether every batch holds demonstrations of one length (for time-indexed policies).
    """

    observation_model: object
    batches: tuple[np.ndarray, ...]
    obs: tuple[np.ndarray, ...]
    lengths: tuple[np.ndarray, ...]
    factors: tuple[ObservationFactors | None, ...]
    n_demos: int
    equal_lengths: bool


def group_by_length(demos: Sequence[Demonstration]) -> dict[int, np.ndarray]:
    """Indices of the demonstrations of each length, ``{T: indices}``, for batching.

    Parameters
    ----------
    demos : sequence of Demonstration

    Returns
    -------
    dict of int to ndarray of int
        Length ``T`` -> the indices of the demonstrations of that length, shortest first.
    """
    groups: dict[int, list[int]] = {}
    for i, d in enumerate(demos):
        groups.setdefault(len(d), []).append(i)
    return {T: np.array(idx) for T, idx in sorted(groups.items())}


def _padded_batches(lengths: np.ndarray, slack: float) -> list[np.ndarray]:
    """Demonstrations by decreasing length, cut where padding would exceed ``slack`` of the
    batch's real steps: one batch when lengths are alike, a few when they are not."""
    order = np.argsort(-lengths, kind="stable")
    batches: list[list[int]] = []
    longest = real = 0
    for i in order:
        n = int(lengths[i])
        if batches and (len(batches[-1]) + 1) * longest <= (1.0 + slack) * (real + n):
            batches[-1].append(int(i))
            real += n
        else:
            batches.append([int(i)])
            longest = real = n
    return [np.sort(np.array(b)) for b in batches]


def pack_demonstrations(
    demos: Sequence[Demonstration], observation_model, *, equal_lengths: bool = False,
    cache: bool = True,
) -> PackedDemonstrations:
    """Validate and pack demonstrations into batches (see the module docstring).

    Parameters
    ----------
    demos : sequence of Demonstration
    observation_model : ObservationModel
    equal_lengths : bool
        One batch per length (needed for time-indexed policies); otherwise ragged lengths share
        padded batches.
    cache : bool
        Keep the observations' log-likelihoods when they fit in ``_CACHE_ELEMENTS`` floats.

    Returns
    -------
    PackedDemonstrations
        For :func:`posterior_stats`, reused over the passes of a fit.
    """
    demos = check_demonstrations(demos, observation_model.n_observations)
    lengths = np.array([len(d) for d in demos])
    if equal_lengths:
        batches = list(group_by_length(demos).values())
    else:
        batches = _padded_batches(lengths, _PAD_SLACK)
    obs, lens, factors = [], [], []
    S, A = observation_model.n_states, observation_model.n_actions
    budget = _CACHE_ELEMENTS if cache else 0
    for idx in batches:
        longest = int(lengths[idx].max())
        packed = np.full((len(idx), longest), -1, dtype=np.int64)
        for row, i in enumerate(idx):
            packed[row, : lengths[i]] = demos[i].as_array()
        obs.append(packed)
        lens.append(lengths[idx])
        size = packed.size * S * A
        if size <= budget:
            factors.append(observation_factors(observation_model, packed))
            budget -= size
        else:
            factors.append(None)
    return PackedDemonstrations(
        observation_model=observation_model, batches=tuple(batches), obs=tuple(obs),
        lengths=tuple(lens), factors=tuple(factors), n_demos=len(demos),
        equal_lengths=equal_lengths,
    )


class _Emissions:
    """The observations of a batch, as the two passes read them."""

    def __init__(self, observation_model, obs, factors: ObservationFactors | None) -> None:
        self.observation_model = observation_model
        self.obs = obs
        self.factors = factors

    def steps(self, t0: int, t1: int) -> ObservationFactors:
        """Shifted likelihoods of steps t0..t1-1 (kept, or computed now)."""
        if self.factors is not None:
            return self.factors.steps(t0, t1)
        return observation_factors(self.observation_model, self.obs[:, t0:t1])

    def separable(self, t0: int, t1: int):
        """``(state, action, shift, min_log)`` of steps t0..t1-1 when the model's likelihoods
        factor into a state and an action part
        (:meth:`irl.observation.ObservationModel.separable_likelihoods`), else None."""
        return self.observation_model.separable_likelihoods(self.obs[:, t0:t1])

    def kronecker(self, t0: int, t1: int):
        """``(head, tail, action, shift, min_log)`` of steps t0..t1-1 when the model's state
        parts are themselves a product of two
        (:meth:`irl.observation.ObservationModel.kronecker_likelihoods`), else None."""
        return self.observation_model.kronecker_likelihoods(self.obs[:, t0:t1])

    def log(self, t: int) -> np.ndarray:
        """``log O(obs[:, t] | s, a)``, shape (N, S, A), a fresh array."""
        return self.observation_model.log_likelihoods(self.obs[:, t])
