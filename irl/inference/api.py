"""Forward-backward's entry points: a batch (:func:`forward_backward`; ``method="log"``
keeps every message in log space) and demonstrations of any lengths in batches
(:func:`posterior_stats`), each pass handed to the numba, scaled or log-space kernels.

Layouts: ``log_pi[s, a]`` or ``log_pi[t, s, a]``, packed observations ``obs[n, t]`` (-1 =
occluded or padding), lengths ``lengths[n]``; results ``log_likelihood[n]``,
``occupancy[n, s, a]`` and ``initial[n, s]`` (:class:`~irl.inference.PosteriorStats`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from irl._blas import one_blas_thread
from irl.demonstrations import Demonstration
from irl.inference.compiled import _numba_pass, check_backend
from irl.inference.logspace import _log_pass
from irl.inference.packing import (
    ObservationFactors,
    PackedDemonstrations,
    PosteriorStats,
    _Emissions,
    pack_demonstrations,
)
from irl.inference.scaled import _RENORMALIZE, _scaled_forward_backward
from irl.inference.workspace import _workspace
from irl.mdp import TabularMDP

METHODS = ("auto", "log")

#: Largest ``N S A`` whose scaled pass renormalizes every few steps rather than at each.
_LAZY_ELEMENTS = 1 << 16


def _check_batch(mdp, log_policy, obs, observation_model, lengths, factors, method):
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}; got {method!r}")
    obs = np.asarray(obs)
    if obs.ndim != 2 or obs.shape[1] < 1:
        raise ValueError(f"obs must have shape (N, T) with T >= 1; got {obs.shape}")
    n_demos, length = obs.shape
    if lengths is None:
        lengths = np.full(n_demos, length)
    else:
        lengths = np.asarray(lengths)
        if lengths.shape != (n_demos,) or lengths.min() < 1 or lengths.max() > length:
            raise ValueError(f"lengths must hold {n_demos} lengths in [1, {length}]; got "
                             f"{lengths}")
    if log_policy.ndim == 3 and (log_policy.shape[0] != length or lengths.min() < length):
        raise ValueError(
            f"a time-indexed log_policy needs demonstrations of its length "
            f"{log_policy.shape[0]}; got lengths from {lengths.min()} to {length}"
        )
    S, A = mdp.n_states, mdp.n_actions
    if factors is not None and factors.possible and factors.factor.shape != (
            n_demos, length, A, S):
        raise ValueError(f"factors must be of shape {(n_demos, length, A, S)}; got "
                         f"{factors.factor.shape}")
    return obs, lengths


def forward_backward(
    mdp: TabularMDP,
    log_policy: np.ndarray,
    obs: np.ndarray,
    observation_model,
    *,
    lengths: np.ndarray | None = None,
    factors: ObservationFactors | None = None,
    log_initial: np.ndarray | None = None,
    demo_ids: Sequence[int] | None = None,
    method: str = "auto",
    backend: str = "numpy",
) -> PosteriorStats:
    """Forward-backward for a batch of demonstrations in one pass.

    Parameters
    ----------
    mdp : TabularMDP
    log_policy : ndarray of shape (S, A) or (T, S, A)
        ``log pi(a | s)``, stationary or per time step (e.g.
        :func:`irl.solvers.log_boltzmann_policy`).
    obs : ndarray of int, shape (N, T)
        Observation indices; -1 marks an occluded (or padded) step.
    observation_model : ObservationModel
        Any implementation; only its ``log_likelihoods`` is called.
    lengths : ndarray of int, shape (N,), optional
        Each demonstration's length when the batch is padded (all T by default); the steps
        after it must be -1.
    factors : ObservationFactors, optional
        ``observation_factors(observation_model, obs)``, when the caller keeps it between
        passes.
    log_initial : ndarray of shape (S,), optional
        Log initial state distribution; ``mdp.log_initial`` by default.
    demo_ids : sequence of int, optional
        Indices of these demonstrations in the caller's list, used in error messages.
    method : {"auto", "log"}
        ``"auto"``: the scaled pass, handing over to the log-space pass when its range check
        fails (see :mod:`irl.inference.scaled`); ``"log"``: the log-space pass only.
    backend : {"numpy", "numba"}
        Kernels of the scaled pass (see :data:`~irl.inference.BACKENDS`); equal to rounding.
        ``"numba"`` runs a stationary policy's batch through one compiled loop when its local
        factors are kept, or can be held for the whole batch (as a state and an action part
        when the model factors that way; ``_NUMBA_ELEMENTS``, ``_NUMBA_FACTOR_ELEMENTS``),
        and hands anything else, and any batch its range check refuses, to the numpy passes.

    Returns
    -------
    PosteriorStats
        Per demonstration: ``log P(o_1..T)``, the expected visits of each pair and the
        posterior of the first state.

    Raises
    ------
    ValueError
        If a demonstration has probability zero under the model; the message names the
        demonstration (``demos[i]``) and the first step at which it becomes impossible.

    Notes
    -----
    Only the predicted state marginals ``(T, S, N)`` and the normalizers are stored; the local
    factors are recomputed during the backward pass unless they are kept (the packing's), the
    whole batch fits in one chunk, or a separable model's parts fit in
    ``_SEPARABLE_ELEMENTS``.
    """
    obs, lengths = _check_batch(mdp, log_policy, obs, observation_model, lengths, factors,
                                method)
    log_p0 = mdp.log_initial if log_initial is None else log_initial
    ids = np.arange(obs.shape[0]) if demo_ids is None else np.asarray(demo_ids)
    emissions = _Emissions(observation_model, obs, factors)
    # one BLAS thread on large MDPs (irl._blas): the pass's dot products and matrix products
    with one_blas_thread(mdp.n_states * mdp.n_actions):
        return _passes(mdp, log_policy, emissions, obs, lengths, log_p0, ids, method, backend)


def _passes(mdp, log_policy, emissions: _Emissions, obs, lengths, log_p0, ids, method,
            backend) -> PosteriorStats:
    """The passes of :func:`forward_backward` on checked arguments: the numba or the scaled
    pass, handing over to the log-space one where they cannot take the batch."""
    if method == "auto":
        if check_backend(backend) == "numba":
            stats = _numba_pass(mdp, log_policy, emissions, obs.shape, lengths, log_p0)
            if stats is not None:
                return stats
        try:
            # renormalizing every few steps saves array calls where they cost more than the
            # arithmetic (small batches); it can leave the range where the other cannot
            lazy = obs.shape[0] * mdp.n_states * mdp.n_actions <= _LAZY_ELEMENTS
            stats = _scaled_forward_backward(mdp, log_policy, emissions, obs.shape, lengths,
                                             log_p0, lazy=lazy)
            if stats is _RENORMALIZE:
                stats = _scaled_forward_backward(mdp, log_policy, emissions, obs.shape,
                                                 lengths, log_p0, lazy=False)
        finally:
            _workspace.release()
        if stats is not None:
            return stats
    return _log_pass(mdp, log_policy, emissions, obs, lengths, log_p0, ids)


def posterior_stats(
    mdp: TabularMDP,
    log_policy: np.ndarray | None,
    demos: Sequence[Demonstration] | PackedDemonstrations,
    observation_model=None,
    *,
    log_policies_by_length=None,
    method: str = "auto",
    backend: str = "numpy",
) -> PosteriorStats:
    """:func:`forward_backward` over demonstrations of any lengths, in batches.

    ``log_policy`` is a stationary ``log pi[s, a]``; alternatively ``log_policies_by_length(T)``
    returns a ``(T, S, A)`` log-policy for demonstrations of length T (finite-horizon models).
    ``demos`` may be packed once beforehand (:func:`pack_demonstrations`, with
    ``equal_lengths=True`` for time-indexed policies); then ``observation_model`` is the
    packing's.

    Parameters
    ----------
    mdp : TabularMDP
    log_policy : ndarray of shape (S, A) or None
        ``log pi[s, a]``; None with ``log_policies_by_length``.
    demos : sequence of Demonstration or PackedDemonstrations
    observation_model : ObservationModel, optional
        Needed unless ``demos`` is packed.
    log_policies_by_length : callable ``T -> ndarray of shape (T, S, A)``, optional
        A time-indexed log-policy per demonstration length (keyword only).
    method, backend : str
        As :func:`forward_backward`'s.

    Returns
    -------
    PosteriorStats
        One row per demonstration, in the order of ``demos``.
    """
    if isinstance(demos, PackedDemonstrations):
        packed = demos
        if log_policies_by_length is not None and not packed.equal_lengths:
            raise ValueError("log_policies_by_length needs demos packed with "
                             "equal_lengths=True; got a ragged packing")
    else:
        packed = pack_demonstrations(demos, observation_model,
                                     equal_lengths=log_policies_by_length is not None,
                                     cache=False)
    om = packed.observation_model
    n = packed.n_demos
    in_order = len(packed.batches) == 1 and np.array_equal(packed.batches[0], np.arange(n))
    ll = np.empty(n)
    occ = np.empty((n, mdp.n_states, mdp.n_actions))
    init = np.empty((n, mdp.n_states))
    for idx, obs, lengths, factors in zip(packed.batches, packed.obs, packed.lengths,
                                          packed.factors, strict=True):
        pol = log_policy if log_policies_by_length is None else log_policies_by_length(
            obs.shape[1])
        stats = forward_backward(mdp, pol, obs, om, lengths=lengths, factors=factors,
                                 demo_ids=idx, method=method, backend=backend)
        if in_order:
            return stats  # one batch in the caller's order: nothing to reassemble
        ll[idx], occ[idx], init[idx] = stats.log_likelihood, stats.occupancy, stats.initial
    return PosteriorStats(log_likelihood=ll, occupancy=occ, initial=init)
