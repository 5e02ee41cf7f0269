"""Exact inference over the hidden state-action sequence of observed demonstrations.

Layouts: ``log_pi[s, a]`` or ``log_pi[t, s, a]``, packed observations ``obs[n, t]``
(-1 = occluded or padding), lengths ``lengths[n]``, log-likelihoods of the observations
``log O(obs[n, t] | s, a)`` (0 at occluded steps) kept as ``factor[n, t, a, s] =
exp(log O - shift[n, t])`` with ``shift[n, t] = max_{s, a} log O``. The scaled pass holds a
batch's messages action-major with the demonstrations innermost, ``alpha[a, s, n]`` and
``pred[s, n]`` (its sparse products then read and write their blocks in place, and a state
array broadcasts over the few actions as whole ``(S, N)`` slabs); its results are returned as
``[n, s, a]`` like everything else. Where it goes by blocks of states (a separable model under
a stationary policy on a sparse MDP), a block's pairs are ``[a, s, n]`` over the block's
states alone, and a step's ``(A, S, N)`` message is never held whole.

A demonstration is a hidden Markov model over ``x_t = (s_t, a_t)``:
``P(x_1) = p0(s_1) pi(a_1 | s_1)``,
``P(x_{t+1} | x_t) = T(s_t, a_t, s_{t+1}) pi(a_{t+1} | s_{t+1})``,
emission ``O(o_t | s_t, a_t)`` (1 when step t is occluded). The forward-backward algorithm
computes ``log P(o_1..T)`` and the posterior marginals ``P(s_t, a_t | o)`` exactly in
``O(T (nnz(T) + S A))`` per demonstration, independent of how many steps are occluded. The
pair transition never materializes: the forward message is pushed through ``T`` and then
multiplied by ``pi``. The emissions come from the observation model one block of steps at a
time (:meth:`irl.observation.ObservationModel.log_likelihoods`), so no dense ``O[s, a, o]`` is
needed.

Batching. All demonstrations of a batch go through one pass: at each step one sparse product
``T`` times the dense block ``(N, S A)`` of their messages replaces N matrix-vector products.
Demonstrations of different lengths share a batch padded to the longest of them; a padded step
contributes nothing (its normalizer is left out of the likelihood, its posterior out of the
occupancy, and the backward message restarts at 1 at each demonstration's last step), so the
result is the same as one pass per demonstration. A time-indexed policy (steps to go) needs
equal lengths per batch.

Numerics. The policy and the emissions come in as log-probabilities, so a Boltzmann policy of
any temperature is represented exactly (``log_softmax``, never ``exp`` then ``log``). Each step's
observation log-likelihood is shifted by its maximum over pairs before it is exponentiated
(a whole chunk of steps at once; for one fit the packed demonstrations keep the result, since
the observations do not change with theta), and the local factor is multiplied into the
predicted state distribution (a stationary policy is folded into ``T``'s pair rows once per
pass instead). Messages are renormalized (Rabiner scaling) and ``shift + log(normalizer)``
summed, as in dynamax's filter, but only every few steps: as often as the smallest local
factor requires for the mass to fall by less than ``e^(-F/4)`` in between. A step's normalizer
may be any positive number, 1 included (the likelihood adds its log and the backward pass
divides by the same one), except at a demonstration's last step, where it must be the sum of
the forward message; where the observations factor into a state part and an action part, it
is the pushed mass, which is that sum (as far as T's rows sum to 1) without a pass over the
message. This scaled pass is exact to rounding as long as every positive shifted local
factor and every positive predicted probability stays above ``e^-F``, about ``e^-340`` (``F``
depends on the smallest transition probability, :func:`_scaled_floor`), so that no product of
them underflows; it checks that. When the check fails (large reward weights make the policy
nearly deterministic, so that a message would span more than the range of a float), the batch is
recomputed by :func:`log_forward_backward`, which keeps every message in log space
(``logsumexp`` through the sparse transition operator) and is exact at any dynamic range, at
about three times the cost. A 10,000-step demonstration neither underflows nor overflows on
either path.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from irl._blas import one_blas_thread
from irl._validation import describe
from irl.demonstrations import Demonstration, check_demonstrations
from irl.mdp import TabularMDP
from irl.observation.base import finite_min

__all__ = [
    "BACKENDS",
    "ObservationFactors",
    "PackedDemonstrations",
    "PosteriorStats",
    "check_backend",
    "forward_backward",
    "group_by_length",
    "log_forward_backward",
    "observation_factors",
    "pack_demonstrations",
    "posterior_stats",
    "scratch_held",
]

METHODS = ("auto", "log")
#: Kernels of the scaled pass: numpy and scipy (the default and the reference), or the
#: compiled loop of :mod:`irl._numba` (``pip install onionsort[fast]``).
BACKENDS = ("numpy", "numba")

#: Steps of local factors (N * steps * S * A floats) exponentiated at once.
_CHUNK_ELEMENTS = 1 << 19
#: Largest ``N T S A`` whose observation log-likelihoods a packing keeps for reuse (32 MB).
_CACHE_ELEMENTS = 1 << 22
#: Largest state parts (``N T S`` floats) the numba backend computes for a whole batch (1 GiB),
#: and largest local factors (``N T S A``) it computes when the model does not factor (256 MB;
#: beyond that the numpy pass, which computes them chunk by chunk, is as fast).
_NUMBA_ELEMENTS = 1 << 27
_NUMBA_FACTOR_ELEMENTS = 1 << 25
#: Largest separable observation parts (``N T S`` floats) the scaled pass computes once for
#: both of its passes (128 MB); beyond that, chunk by chunk in each.
_SEPARABLE_ELEMENTS = 1 << 24
#: Largest scratch array (floats) a thread keeps between passes (8 MB).
_WORKSPACE_ELEMENTS = 1 << 20
#: Floats of one block of states (``block A N``) that the scaled pass computes at once
#: where it goes by blocks (a separable model, a stationary policy, a sparse MDP; 1 MB, a
#: core's L2 cache on the machine of docs/performance.md): the step's ``(A, S, N)`` message
#: then stays in the cache at any S.
_BLOCK_ELEMENTS = 1 << 17
#: Largest ``N S A`` whose scaled pass renormalizes every few steps rather than at each.
_LAZY_ELEMENTS = 1 << 16
#: What the scaled pass returns when renormalizing at every step may keep it in range.
_RENORMALIZE = object()
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
    :meth:`irl.observation.ObservationModel.scaled_likelihoods`."""
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
    """Indices of the demonstrations of each length, ``{T: indices}``, for batching."""
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


class _Workspace(threading.local):
    """Scratch arrays of the scaled pass, kept between calls in one thread.

    A fit runs forward-backward on the same shapes a few dozen times; a fresh array comes from
    the operating system as untouched pages, and faulting them in can cost more than the
    arithmetic on them (on a virtual machine, memory freed a few seconds earlier may have been
    handed back to the host, and faulting it in again took about 2 ms per MB on the 2-core VM
    of the figures in docs/performance.md). Every array is kept until the pass ends, so that a
    pass asks for each of its arrays once; then those above ``_WORKSPACE_ELEMENTS`` floats are
    dropped, unless the caller holds them for its next passes (:func:`scratch_held`).
    """

    def __init__(self) -> None:
        self.arrays: dict[str, np.ndarray] = {}
        self.holders = 0

    def get(self, name: str, shape: tuple[int, ...]) -> np.ndarray:
        """An uninitialized float array of ``shape``, reused when the last one fits."""
        a = self.arrays.get(name)
        if a is None or a.shape != shape:
            a = self.arrays[name] = np.empty(shape)
        return a

    def release(self) -> None:
        """Drop the arrays above ``_WORKSPACE_ELEMENTS`` floats, unless they are held."""
        if self.holders:
            return
        for name in [k for k, a in self.arrays.items() if a.size > _WORKSPACE_ELEMENTS]:
            del self.arrays[name]


_workspace = _Workspace()


@contextmanager
def scratch_held():
    """Keep the scaled pass's large scratch arrays between the passes run inside (in this
    thread), and drop them at the end.

    A fit runs forward-backward once per gradient on the same shapes; at S = 100,000 its
    predicted marginals alone are 800 MB, faulted in afresh by every pass unless held. The
    learners hold them for the length of a fit; a single pass drops them when it ends.
    """
    _workspace.holders += 1
    try:
        yield
    finally:
        _workspace.holders -= 1
        _workspace.release()


def _logsumexp(x: np.ndarray, axis) -> np.ndarray:
    """``log sum exp`` over ``axis``; ``-inf`` where every term is ``-inf`` (no warnings)."""
    top = np.max(x, axis=axis, keepdims=True)
    top = np.where(np.isfinite(top), top, 0.0)
    with np.errstate(divide="ignore"):
        out = np.log(np.sum(np.exp(x - top), axis=axis, keepdims=True)) + top
    return np.squeeze(out, axis=axis)


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


def _impossible(ids, obs, n: int, t: int) -> ValueError:
    return ValueError(
        f"demos[{ids[n]}], step {t}: observation {int(obs[n, t])} is impossible under the "
        "model given the steps before it (its probability is zero); check the observation "
        "model and the demonstration"
    )


def check_backend(backend) -> str:
    """``backend`` if it is one of :data:`BACKENDS` and can run here; else a ValueError
    (TypeError) that names it."""
    if not isinstance(backend, str):
        raise TypeError(f"backend must be one of {BACKENDS}; got {describe(backend)}")
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}; got {backend!r}")
    if backend == "numba":
        from irl import _numba

        if not _numba.available():
            raise ValueError("backend 'numba' needs numba, which is not installed: "
                             "pip install 'onionsort[fast]' (or pip install numba)")
    return backend


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
        fails (see the module docstring); ``"log"``: the log-space pass only.
    backend : {"numpy", "numba"}
        Kernels of the scaled pass (see :data:`BACKENDS`); equal to rounding. ``"numba"`` runs
        a stationary policy's batch through one compiled loop when its local factors are kept,
        or can be held for the whole batch (as a state and an action part when the model
        factors that way; ``_NUMBA_ELEMENTS``, ``_NUMBA_FACTOR_ELEMENTS``), and hands anything
        else, and any batch its range check refuses, to the numpy passes.

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


def _numba_pass(mdp, log_policy, emissions: _Emissions, shape, lengths, log_p0):
    """The scaled pass as one compiled loop (:mod:`irl._numba`); ``None`` when it does not
    apply (a time-indexed policy, a batch whose local factors are too large to hold) or its
    range check fails. A batch whose factors are not kept goes in as a state part and an action
    part when the model factors that way (``N T S`` floats instead of ``N T S A``), its state
    part as two factors where the model reads the state that way (``N T (S / n + n)``)."""
    from irl import _numba

    n_demos, length = shape
    S, A = mdp.n_states, mdp.n_actions
    F = _scaled_floor(mdp)
    if log_policy.ndim != 2 or F < 20.0:
        return None
    log_pi_min = finite_min(log_policy)
    csr = mdp._action_major_csr
    operator = (csr.indptr, csr.indices, csr.data)
    pi = np.ascontiguousarray(np.exp(log_policy).T)
    tail_args = (np.asarray(lengths, dtype=np.int64), np.exp(log_p0), float(F))
    parts = kron = None
    if emissions.factors is None:  # the state parts as two factors, else whole if they fit
        kron = emissions.kronecker(0, length)
        if kron is None and n_demos * length * S <= _NUMBA_ELEMENTS:
            parts = emissions.separable(0, length)
    if kron is not None:
        head, tail, action, shift, min_log = kron
        if min_log + log_pi_min < -F:
            return None
        ok, ll, occupancy, initial = _numba.scaled_forward_backward_kronecker(
            *operator, pi, head, tail, action, shift, *tail_args)
    elif parts is not None:
        state, action, shift, min_log = parts
        if min_log + log_pi_min < -F:
            return None
        ok, ll, occupancy, initial = _numba.scaled_forward_backward_separable(
            *operator, pi, state, action, shift, *tail_args)
    else:
        if emissions.factors is None and n_demos * length * S * A > _NUMBA_FACTOR_ELEMENTS:
            return None  # the numpy pass computes them chunk by chunk instead
        blk = emissions.steps(0, length)
        if not blk.possible or blk.min_log + log_pi_min < -F:
            return None
        ok, ll, occupancy, initial = _numba.scaled_forward_backward(
            *operator, pi, blk.factor, blk.shift, *tail_args)
    if not ok:
        return None
    return PosteriorStats(log_likelihood=ll, occupancy=occupancy, initial=initial)


def _scaled_floor(mdp: TabularMDP) -> float:
    """``F``: the scaled pass keeps local factors and predicted probabilities above ``e^-F``.

    Then ``alpha = pred * local >= e^-2F``, and pushed through ``T`` (entries at least
    ``t_min``) with normalizer at most ``S A``, it stays above ``e^-690``: nothing that is
    positive underflows to 0 (a float's smallest normal number is about ``e^-708``).
    """
    return (690.0 + mdp.min_log_transition - math.log(mdp.n_states * mdp.n_actions)) / 2.0


def _chunks(length: int, per_step: int) -> list[tuple[int, int]]:
    size = max(1, _CHUNK_ELEMENTS // max(per_step, 1))
    return [(t0, min(t0 + size, length)) for t0 in range(0, length, size)]


def _scaled_forward_backward(mdp, log_policy, emissions: _Emissions, shape, lengths, log_p0,
                             lazy: bool = True):
    """The scaled pass; ``None`` when a message would leave its safe range (see module), and
    ``_RENORMALIZE`` when it left it renormalizing every few steps (``lazy``), which fewer
    mass lost between renormalizations may avoid.

    Layout: the batch's messages are held in columns, demonstrations innermost (``pred[s, n]``,
    ``alpha[a, s, n]``), so that the two sparse products of a step read and write their blocks
    in place and a state array broadcasts over the actions as whole ``(S, N)`` slabs. A
    stationary policy is folded into the products (:meth:`TabularMDP.column_products`), so the
    local factors ``E[t, a, s, n]`` are the observations' alone (kept in this layout by the
    packing for a whole fit); a time-indexed one is multiplied in, a chunk of steps at once. A
    step of the forward pass is then two to four array operations (``alpha = E_t pred_t``, the
    push through ``T``, and at a renormalization the sum and the division), a step of the
    backward pass four (the products add into zeros set once per pass, and each beta is
    received where it becomes gamma), and the posteriors of a whole chunk are formed at once.
    When the observations are computed chunk by chunk (too many to keep) and the model's
    likelihoods are a state part times an action part
    (:meth:`~irl.observation.ObservationModel.separable_likelihoods`), ``E`` is never formed:
    ``alpha_t / pi = (e_t pred_t) e'_t``. Under a stationary policy on a sparse MDP such a
    pass then goes by blocks of states (``_BLOCK_ELEMENTS``; :func:`_block_push`,
    :func:`_blocked_backward`): a block's products, its action part and its sum over the
    actions are done while its ``(A, block, N)`` pairs are in the cache, so that no ``(A, S,
    N)`` message goes through memory, which at 100,000 states (33 MB for 10 demonstrations)
    it would at every step, several times.
    """
    n_demos, length = shape
    S, A = mdp.n_states, mdp.n_actions
    F = _scaled_floor(mdp)
    if F < 20.0:
        return None
    log_pi_min = finite_min(log_policy)
    pi = np.exp(np.swapaxes(log_policy, -1, -2))  # [.., a, s]
    stationary = log_policy.ndim == 2  # then folded into T's pair rows (see below)
    chunks = _chunks(length, n_demos * S * A)
    ragged = bool(lengths.min() < length)
    ws = _workspace
    separable = (emissions.factors is None and len(chunks) > 1
                 and emissions.separable(0, 1) is not None)
    u = ws.get("u", (S, n_demos)) if separable else None

    def separable_parts(t0, t1, name):
        """``(state[t, s, n], action[t, a, n], shift[n, t], min_log)`` of steps t0..t1-1; the
        state part formed in the workspace array ``name`` from its two factors where the model
        has them (the products :meth:`~irl.observation.ObservationModel.separable_likelihoods`
        forms, bit for bit, in the pass's layout), else views of the model's."""
        kron = emissions.kronecker(t0, t1)
        if kron is None:
            state, action, shift, min_log = emissions.separable(t0, t1)
            return np.moveaxis(state, 0, -1), np.moveaxis(action, 0, -1), shift, min_log
        head, tail, action, shift, min_log = kron
        state = ws.get(name, (t1 - t0, S, n_demos))
        np.multiply(np.moveaxis(head, 0, -1)[:, :, None, :],
                    np.moveaxis(tail, 0, -1)[:, None, :, :],
                    out=state.reshape(t1 - t0, head.shape[-1], tail.shape[-1], n_demos))
        return state, np.moveaxis(action, 0, -1), shift, min_log

    # the separable parts of every step, when small enough to hold for both passes
    whole = (separable_parts(0, length, "whole") if separable
             and n_demos * length * S <= _SEPARABLE_ELEMENTS else None)

    def local(t0, t1):
        """The chunk's local factors and the log of their smallest positive entry, ``(E[t, a,
        s, n], shift[n, t], min_log)``, or ``((state[t, s, n], action[t, a, n]), shift,
        min_log)`` when separable (the state part valid until the next call); None outside
        the safe range. ``E`` leaves out the policy where it is folded into T."""
        if separable:
            if whole is not None:
                state, action, shift, min_log = whole
                state, action, shift = state[t0:t1], action[t0:t1], shift[:, t0:t1]
            else:
                state, action, shift, min_log = separable_parts(t0, t1, "state")
            if not np.all(np.isfinite(shift)) or min_log + log_pi_min < -F:
                return None
            return (state, action), shift, min_log
        blk = emissions.steps(t0, t1)
        if not blk.possible:
            return None  # a step no pair can emit: the log-space pass names it
        if blk.min_log + log_pi_min < -F:
            return None
        if stationary and emissions.factors is not None:  # kept in columns for every pass
            return emissions.factors.columns[t0:t1], blk.shift, blk.min_log
        E = ws.get("E", (t1 - t0, A, S, n_demos))
        if stationary:
            np.copyto(E, np.moveaxis(blk.factor, 0, -1))
        else:
            np.multiply(np.moveaxis(blk.factor, 0, -1), pi[t0:t1, ..., None], out=E)
        return E, blk.shift, blk.min_log

    def times_local(E, i, t, vec, out):
        """``out[a, s, n] = E_t[a, s, n] vec`` for step t (i within its chunk), ``vec`` of
        shape (S, N) or (A, S, N), when the factors are separable and the policy is
        time-indexed (else the loops multiply by ``E[i]`` or fold the policy into T)."""
        state, action = E
        policy = pi[t][:, :, None]
        if vec.ndim == 2:  # pi (e_t pred): the state part joins the (S, N) vector
            np.multiply(policy, np.multiply(state[i], vec, out=u), out=out)
        else:  # the state part is applied by the caller, on the (S, N) sum
            np.multiply(vec, policy, out=out)
        out *= action[i][:, None, :]

    # a separable model under a stationary policy goes by blocks of states (_block_push,
    # _blocked_backward); None where the MDP's products are dense
    block = min(S, max(1, _BLOCK_ELEMENTS // (A * n_demos)))
    blocked = (mdp.state_block_products(block, n_demos, np.exp(log_policy).ravel())
               if separable and stationary else None)
    preds = ws.get("preds", (length, S, n_demos))
    shifts = ws.get("shifts", (length, n_demos))
    norms = ws.get("norms", (length, n_demos))
    preds[0] = np.exp(log_p0)[:, None]
    if blocked is None:
        preds[1:] = 0.0  # the pushes add into it (the blocks write theirs)
    else:
        blocks = _Blocks(S, A, n_demos, block, ws)
    preds_1d = preds.reshape(length, S * n_demos)
    if blocked is None:
        alpha = ws.get("alpha", (A, S, n_demos))
        alpha_flat = alpha.reshape(A * S, n_demos)
        alpha_1d = alpha.reshape(-1)
        pair_weights = pi.ravel() if stationary else np.ones(A * S)  # alpha's sum: w alpha
        push, expect = mdp.column_products(n_demos, pair_weights if stationary else None)
    closing = np.zeros(length, dtype=bool)  # the steps at which some demonstration ends
    closing[lengths - 1] = True
    single = len(chunks) == 1
    norms[...] = 1.0  # a step not renormalized keeps 1
    since = 0  # steps since the last renormalization
    lazy_used = False
    kept = None
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for t0, t1 in chunks:
            got = local(t0, t1)
            if got is None:
                return None
            E, shifts[t0:t1] = got[0], got[1].T
            # renormalize every `every` steps: where every pair can emit what is seen, the
            # mass falls by at most e^min_log a step (the policy sums to 1), so by at most
            # e^(-F/4) between renormalizations; the range check below covers the rest
            every = max(1, int(F / (4.0 * max(-got[2], 1.0)))) if lazy else 1
            lazy_used = lazy_used or every > 1
            if separable and stationary:  # alpha / pi = e'_t (e_t pred_t), pi in the pushes
                for t in range(t0, t1):
                    state, action = E[0][t - t0], E[1][t - t0]
                    np.multiply(state, preds[t], out=u)
                    if blocked is None:
                        np.multiply(action[:, None, :], u, out=alpha)
                    since += 1
                    if closing[t]:  # the likelihood's own sum: sum_s e_t pred_t (pi' e'_t)
                        np.einsum("sn,sn->n", u, pi.T @ action, out=norms[t])
                    if t + 1 < length:
                        if blocked is None:
                            push(alpha_1d, preds_1d[t + 1])
                        else:
                            _block_push(blocked[0], u, action, preds[t + 1], blocks)
                        if closing[t] or since >= every:
                            if not closing[t]:  # the pushed mass: alpha's sum without a
                                # pass over alpha (see the module's numerics)
                                np.add.reduce(preds[t + 1], axis=0, out=norms[t])
                            preds[t + 1] /= norms[t]
                            since = 0
                continue
            for t in range(t0, t1):  # alpha, or alpha / pi when pi is in the pushes
                if separable:
                    times_local(E, t - t0, t, preds[t], alpha)
                else:
                    np.multiply(E[t - t0], preds[t], out=alpha)
                since += 1
                if closing[t] or since >= every:
                    np.dot(pair_weights, alpha_flat, out=norms[t])
                    if t + 1 < length:  # push, then normalize the (S, N) result
                        push(alpha_1d, preds_1d[t + 1])
                        preds[t + 1] /= norms[t]
                    since = 0
                elif t + 1 < length:
                    push(alpha_1d, preds_1d[t + 1])
        if single:
            kept = E  # the backward pass reuses it
        # out of range: with fewer renormalizations than steps, the caller tries again
        # renormalizing at every step; else the log-space pass takes over (and names an
        # impossible demonstration)
        out_of_range = _RENORMALIZE if lazy_used else None
        if not norms.min() > 0.0:
            return out_of_range
        tiny = np.exp(-F)
        step = max(1, _CHUNK_ELEMENTS // (n_demos * S))
        for t0 in range(0, length, step):  # in chunks: no (T, S, N) temporaries
            p = preds[t0:t0 + step]
            if ((p < tiny) & (p > 0.0)).any():
                return out_of_range

        # beta_t(s, a) = sum_s' T(s, a, s') sum_a' pi(a'|s') e_{t+1}(s', a') beta_{t+1}(s', a'),
        # divided by c_{t+1} (Rabiner scaling), so that alpha_t * beta_t is the posterior
        # marginal of step t. The local factors carry the forward pass's shifts, so alpha_t
        # and beta_t are scaled consistently. A state the forward pass cannot reach at step t
        # gets g = 0: no pair with forward mass leads there, and so every beta stays below
        # about e^F. Padded steps (t >= lengths[n]) add nothing, and beta restarts at 1 at
        # each last step.
        inv_norms = np.divide(1.0, norms, out=ws.get("inv_norms", norms.shape))
        scale = preds  # becomes pred_t / c_t in place (T, S, N): no second copy
        scale *= inv_norms[:, None, :]
        if ragged:
            valid = np.arange(length)[:, None] < lengths[None, :]  # (T, N)
            scale *= valid[:, None, :]
            last = lengths - 1
        if blocked is not None:
            occupancy, initial = _blocked_backward(
                blocked[1], chunks, kept, local, scale, inv_norms, lengths if ragged else None,
                pi, blocks, ws)
            return _finish(occupancy, initial, shifts, norms, valid if ragged else None)
        occupancy = np.zeros((A, S, n_demos))
        restart = pi[:, :, None] if stationary else 1.0  # pi beta when pi is folded into T
        beta = ws.get("beta", (A, S, n_demos))
        beta[...] = restart
        beta_1d = beta.reshape(-1)
        g = ws.get("g", (S, n_demos))
        g_1d = g.reshape(-1)
        for t0, t1 in reversed(chunks):
            E = kept if kept is not None else local(t0, t1)[0]
            # unreachable states send nothing back (scale_t > 0 iff pred_t > 0 at a real
            # step; padded steps are zeroed and send nothing either)
            sends = ws.get("sends", (t1 - t0, S, n_demos))
            np.multiply(scale[t0:t1] > 0.0, inv_norms[t0:t1, None, :], out=sends)
            weights = scale[t0:t1]  # (L, S, N): the posterior is gamma times this
            if separable:
                sends *= E[0]
                weights = weights * E[0]
            gamma = ws.get("gamma", (t1 - t0, A, S, n_demos))  # pi e_t beta_t of the chunk
            gamma_1d = gamma.reshape(t1 - t0, -1)
            if single:  # every beta is received in gamma, where it becomes gamma in place
                gamma[:-1] = 0.0
                gamma[-1] = restart
            for t in range(t1 - 1, t0 - 1, -1):
                gamma_t = gamma[t - t0]
                beta_t = gamma_t if single else beta
                if ragged:
                    ends = last == t
                    if ends.any():
                        beta_t[:, :, ends] = restart
                if separable and stationary:
                    np.multiply(beta_t, E[1][t - t0][:, None, :], out=gamma_t)
                elif separable:
                    times_local(E, t - t0, t, beta_t, gamma_t)
                else:
                    np.multiply(E[t - t0], beta_t, out=gamma_t)
                if t > 0:
                    np.add.reduce(gamma_t, axis=0, out=g)
                    g *= sends[t - t0]
                    if single:
                        expect(g_1d, gamma_1d[t - 1])
                    else:
                        beta.fill(0.0)
                        expect(g_1d, beta_1d)
            gamma *= weights[:, None]
            occupancy += gamma[0] if t1 - t0 == 1 else np.add.reduce(gamma, axis=0)
        initial = np.ascontiguousarray(gamma[0].sum(axis=0).T)
    return _finish(occupancy.transpose(2, 1, 0), initial, shifts, norms, valid if ragged else None)


def _finish(occupancy, initial, shifts, norms, valid) -> PosteriorStats | None:
    """:class:`PosteriorStats` of the scaled pass from ``occupancy[n, s, a]`` and
    ``initial[n, s]`` (views), its shifts and normalizers ``(T, N)`` and the mask of real steps
    ``valid[t, n]`` (None: every step is real); None where they are not finite."""
    if not np.isfinite(occupancy.sum() + initial.sum()):  # (each entry is at most T)
        return None
    per_step = shifts + np.log(norms)
    if valid is not None:
        per_step = np.where(valid, per_step, 0.0)
    return PosteriorStats(log_likelihood=per_step.sum(axis=0),
                          occupancy=np.ascontiguousarray(occupancy),
                          initial=np.ascontiguousarray(initial))


class _Blocks:
    """The blocks of states of a blocked pass and the views of its scratch that each block
    reads and writes, made once per pass (the loops then make few Python objects per block).

    Attributes
    ----------
    spans : list of (int, int)
        Each block's states ``s0..s1-1``.
    pairs : list of ndarray
        Each block's pairs, flat (``A m N``, one scratch array for all).
    cubes : list of ndarray
        The same as ``(A, m, N)``.
    act : ndarray of shape (A, block, N)
        A step's action part, repeated over a block's states.
    acts : list of ndarray
        Its ``(A, m, N)`` view for each block.
    """

    def __init__(self, S: int, A: int, n_demos: int, block: int, ws: _Workspace) -> None:
        buf = ws.get("block", (A * block * n_demos,))
        self.act = ws.get("act", (A, block, n_demos))
        self.spans = [(s0, min(s0 + block, S)) for s0 in range(0, S, block)]
        self.pairs = [buf[:A * (s1 - s0) * n_demos] for s0, s1 in self.spans]
        self.cubes = [p.reshape(A, -1, n_demos) for p in self.pairs]
        self.acts = [self.act[:, :s1 - s0] for s0, s1 in self.spans]

    def rows(self, array: np.ndarray, axis: int = 0) -> list[np.ndarray]:
        """The view of each block's states in ``array``, whose axis ``axis`` is the state."""
        lead = (slice(None),) * axis
        return [array[(*lead, slice(s0, s1))] for s0, s1 in self.spans]


def _block_push(push, u, action, out, blocks: _Blocks) -> None:
    """``out[s', n] = sum_{s, a} T[s, a, s'] pi(a | s) u[s, n] e'[a, n]``: the forward
    pass's push of ``alpha = u e'`` (``u = e_t pred_t`` (S, N), ``e'`` the action part (A, N)),
    block by block of next states (:meth:`TabularMDP.state_block_products`), so that alpha is
    never formed whole."""
    np.copyto(blocks.act, action[:, None, :])  # then the block's products run over whole slabs
    u_1d = u.reshape(-1)
    for k, (s0, s1) in enumerate(blocks.spans):
        flat, b = blocks.pairs[k], blocks.cubes[k]
        flat.fill(0.0)
        push(k, u_1d, flat)
        b *= blocks.acts[k]
        np.add.reduce(b, axis=0, out=out[s0:s1])


def _blocked_backward(expect, chunks, kept, local, scale, inv_norms, lengths, pi,
                      blocks: _Blocks, ws):
    """The backward pass of a separable model under a stationary policy, block by block of
    states (:meth:`TabularMDP.state_block_products`): ``(occupancy[n, s, a], initial[n, s])``,
    C-contiguous.

    At step t, a block's ``pi beta_t[a, s, n]`` (``pi[a, s]`` at a demonstration's last step,
    else ``pi`` times the expectation of ``g_{t+1}``) is multiplied by the action part
    ``e'_t[a, n]`` into gamma; ``g_t = sends_t sum_a gamma`` goes back to step t - 1, and
    gamma times the state weights ``scale_t e_t`` is the block's posterior. At step 0 a
    block's occupancy is complete, and is written to the ``[n, s, a]`` result while it is in
    the cache (a transposed copy of the whole ``(A, S, N)`` array afterwards reads it from
    memory once per demonstration at large S). ``scale`` (T, S, N)
    is ``pred_t / c_t`` (zero at padded steps), ``lengths`` None when every demonstration is as
    long as the batch; ``ws`` is the thread's :class:`_Workspace`.
    """
    length, S, n_demos = scale.shape
    A = pi.shape[0]
    occupancy = ws.get("occupancy", (A, S, n_demos))
    occupancy.fill(0.0)
    result = np.empty((n_demos, S, A))
    initial = np.empty((n_demos, S))
    g_next, g_cur = ws.get("g", (S, n_demos)), ws.get("g2", (S, n_demos))
    restarts = blocks.rows(pi[:, :, None], axis=1)
    occupancies = blocks.rows(occupancy, axis=1)
    results = [r.transpose(2, 1, 0) for r in blocks.rows(result, axis=1)]  # [a, s, n] views
    initials = [r.T for r in blocks.rows(initial, axis=1)]
    g_rows = {id(g): blocks.rows(g) for g in (g_next, g_cur)}
    # a block's sends and state weights, formed in the block's loop (in the cache)
    block = blocks.act.shape[1]
    sends_buf, weights_buf = (ws.get(name, (block, n_demos)) for name in ("sends", "weights"))
    sends, weights = ([buf[:s1 - s0] for s0, s1 in blocks.spans]
                      for buf in (sends_buf, weights_buf))
    for t0, t1 in reversed(chunks):
        state, action = kept if kept is not None else local(t0, t1)[0]
        for t in range(t1 - 1, t0 - 1, -1):
            i = t - t0
            ends = None if lengths is None else np.flatnonzero(lengths - 1 == t)
            if ends is not None and not ends.size:
                ends = None
            np.copyto(blocks.act, action[i][:, None, :])
            g_1d = g_next.reshape(-1)
            scale_t, state_t, inv_t, g_out = scale[t], state[i], inv_norms[t], g_rows[id(g_cur)]
            for k, (s0, s1) in enumerate(blocks.spans):
                flat, b = blocks.pairs[k], blocks.cubes[k]
                # unreachable states send nothing back (scale_t > 0 iff pred_t > 0 at a real
                # step; padded steps are zeroed and send nothing either); the posterior is
                # gamma times the weights
                sc, st, sends_k, weights_k = scale_t[s0:s1], state_t[s0:s1], sends[k], weights[k]
                np.multiply(sc > 0.0, inv_t, out=sends_k)
                sends_k *= st
                np.multiply(sc, st, out=weights_k)
                if t == length - 1:
                    b[...] = restarts[k]
                else:
                    flat.fill(0.0)
                    expect(k, g_1d, flat)
                    if ends is not None:
                        b[:, :, ends] = restarts[k]
                b *= blocks.acts[k]
                if t > 0:
                    g = np.add.reduce(b, axis=0, out=g_out[k])
                    g *= sends_k
                b *= weights_k
                if t == 0:
                    np.add.reduce(b, axis=0, out=initials[k])
                    np.add(occupancies[k], b, out=results[k])
                else:
                    occupancies[k] += b
            g_next, g_cur = g_cur, g_next
    return result, initial


def log_forward_backward(
    mdp: TabularMDP,
    log_policy: np.ndarray,
    obs: np.ndarray,
    observation_model,
    *,
    lengths: np.ndarray | None = None,
    factors: ObservationFactors | None = None,
    log_initial: np.ndarray | None = None,
    demo_ids: Sequence[int] | None = None,
) -> PosteriorStats:
    """Forward-backward with every message in log space: exact at any dynamic range.

    Arguments as :func:`forward_backward`. The messages are pushed through the transition
    operator with ``logsumexp`` over its positive entries (:meth:`TabularMDP.log_push_forward`,
    :meth:`TabularMDP.log_expect_next`), ``O(T nnz(T))`` exponentials per demonstration.
    """
    obs, lengths = _check_batch(mdp, log_policy, obs, observation_model, lengths, factors,
                                "log")
    log_p0 = mdp.log_initial if log_initial is None else log_initial
    ids = np.arange(obs.shape[0]) if demo_ids is None else np.asarray(demo_ids)
    return _log_pass(mdp, log_policy, _Emissions(observation_model, obs, None), obs, lengths,
                     log_p0, ids)


def _log_pass(mdp, log_policy, emissions: _Emissions, obs, lengths, log_p0,
              ids) -> PosteriorStats:
    n_demos, length = obs.shape
    S, A = mdp.n_states, mdp.n_actions
    valid = np.arange(length)[:, None] < lengths[None, :]  # (T, N)

    log_preds = np.empty((length, n_demos, S))
    log_norms = np.empty((length, n_demos))
    lp = np.repeat(log_p0[None, :], n_demos, axis=0)
    for t in range(length):
        la = emissions.log(t)
        la += log_policy if log_policy.ndim == 2 else log_policy[t]
        la += lp[:, :, None]
        lc = _logsumexp(la, axis=(1, 2))
        bad = ~np.isfinite(lc) & valid[t]
        if bad.any():
            raise _impossible(ids, obs, int(np.flatnonzero(bad)[0]), t)
        log_preds[t], log_norms[t] = lp, lc
        if t + 1 < length:
            la -= lc[:, None, None]
            lp = mdp.log_push_forward(la)

    occupancy = np.zeros((n_demos, S, A))
    log_beta = np.zeros((n_demos, S, A))
    for t in range(length - 1, -1, -1):
        ends = lengths - 1 == t
        log_beta[ends] = 0.0
        lg = emissions.log(t)
        lg += log_policy if log_policy.ndim == 2 else log_policy[t]
        lg += log_beta  # log(pi e_t beta_t)
        log_post = lg + (log_preds[t] - log_norms[t][:, None])[:, :, None]
        post = np.exp(log_post)
        post[~valid[t]] = 0.0
        occupancy += post
        if t > 0:
            log_beta = mdp.log_expect_next(_logsumexp(lg, axis=2))
            log_beta -= log_norms[t][:, None, None]
    return PosteriorStats(
        log_likelihood=np.where(valid, log_norms, 0.0).sum(axis=0),
        occupancy=occupancy,
        initial=post.sum(axis=2),
    )


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
