"""FROZEN COPY, not library code: the forward-backward, planning kernels and MMAP-BIRL
gradient assembly of irl as of commit cfdfae2 (2026-11-23), the baseline that
bench/bench_irl.py times the library against in the same run. Do not edit it to follow the
library, and do not import it elsewhere.

The planning kernels (``OptimalQSolver`` and its helpers, unchanged from cfdfae2 to e77f9cd)
and the gradient's assembly are frozen here too, so that later work on the library's solver
speeds up the library, not its baseline; only the optimizer loop is shared.

It takes the dense emission table ``log E[o, s, a]`` (``observation_model.log_emissions``), packs
the demonstrations at every call and runs one pass per group of equal lengths. Only the names it
shares with the library changed; the kernels are the ones of that commit (the flat-operator
products are inlined as they were).

Why a copy and not a checkout of cfdfae2 (``git worktree``) that the bench imports in a child
process: cfdfae2's code does run on today's numpy and scipy, but

- the baseline is not cfdfae2's learner as a whole: :class:`BaselineMMAPBIRL` is today's
  ``MMAPBIRL`` (its optimizer loop, checks and prior) with cfdfae2's kernels in place of
  today's, so that the bench's speed-ups measure the kernels. A checkout would time cfdfae2's
  own optimizer loop and checks as well: other figures than the ones the docs quote;
- the inputs would not be identical without rebuilding them: the bench hands both paths the
  same estimator objects, prepared data and observation models in one process (the same-theta
  check of [1], the gradient timings on one prepared batch), and section [3] runs the frozen
  path on today's grid (``irl.domains.grid_mdp``) and 100-block state sensor through its dense
  table; cfdfae2 has neither a grid domain nor any observation model but the dense one, so a
  child would need every input serialized and rebuilt in its classes, and its peak memory
  traced there;
- a checkout needs the repository's history where the bench runs, which a source distribution
  or a shallow clone lacks.
"""

from __future__ import annotations

import logging
import warnings
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.special import log_softmax

from irl.demonstrations import Demonstration, pack_observations
from irl.exceptions import ConvergenceWarning
from irl.learners.birl import MMAPBIRL
from irl.mdp import TabularMDP
from irl.priors import GaussianPrior

logger = logging.getLogger(__name__)

_TIE_TOL = 1e-10

__all__ = ["BaselineMMAPBIRL", "posterior_stats"]

METHODS = ("auto", "log")


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


def group_by_length(demos: Sequence[Demonstration]) -> dict[int, np.ndarray]:
    """Indices of the demonstrations of each length, ``{T: indices}``, for batching."""
    groups: dict[int, list[int]] = {}
    for i, d in enumerate(demos):
        groups.setdefault(len(d), []).append(i)
    return {T: np.array(idx) for T, idx in sorted(groups.items())}


def _logsumexp(x: np.ndarray, axis) -> np.ndarray:
    """``log sum exp`` over ``axis``; ``-inf`` where every term is ``-inf`` (no warnings)."""
    top = np.max(x, axis=axis, keepdims=True)
    top = np.where(np.isfinite(top), top, 0.0)
    with np.errstate(divide="ignore"):
        out = np.log(np.sum(np.exp(x - top), axis=axis, keepdims=True)) + top
    return np.squeeze(out, axis=axis)


def _local(log_policy, obs, log_emissions):
    """``t -> log pi(a | s) + log O(o_t | s, a)``, shape (N, S, A), a fresh array per call."""

    def local(t: int) -> np.ndarray:
        e = log_emissions[obs[:, t]]  # contiguous rows: a copy of N blocks
        e += log_policy if log_policy.ndim == 2 else log_policy[t]
        return e

    return local


def _impossible(ids, obs, n: int, t: int) -> ValueError:
    return ValueError(
        f"demos[{ids[n]}], step {t}: observation {int(obs[n, t])} is impossible under the "
        "model given the steps before it (its probability is zero); check the observation "
        "model and the demonstration"
    )


def forward_backward(
    mdp: TabularMDP,
    log_policy: np.ndarray,
    obs: np.ndarray,
    log_emissions: np.ndarray,
    *,
    log_initial: np.ndarray | None = None,
    demo_ids: Sequence[int] | None = None,
    method: str = "auto",
) -> PosteriorStats:
    """Forward-backward for a batch of equal-length demonstrations.

    Parameters
    ----------
    mdp : TabularMDP
    log_policy : ndarray of shape (S, A) or (T, S, A)
        ``log pi(a | s)``, stationary or per time step (e.g.
        :func:`irl.solvers.log_boltzmann_policy`).
    obs : ndarray of int, shape (N, T)
        Observation indices; -1 marks an occluded step.
    log_emissions : ndarray of shape (n_observations + 1, S, A)
        ``log O(o | s, a)`` with a last row of zeros for occluded steps
        (:attr:`irl.observation.ObservationModel.log_emissions`).
    log_initial : ndarray of shape (S,), optional
        Log initial state distribution; ``mdp.log_initial`` by default.
    demo_ids : sequence of int, optional
        Indices of these demonstrations in the caller's list, used in error messages.
    method : {"auto", "log"}
        ``"auto"``: the scaled pass, handing over to the log-space pass when its range check
        fails (see the module docstring); ``"log"``: the log-space pass only.

    Raises
    ------
    ValueError
        If a demonstration has probability zero under the model; the message names the
        demonstration (``demos[i]``) and the first step at which it becomes impossible.

    Notes
    -----
    The emission table is observation-major, so gathering a step's emissions copies contiguous
    blocks. Only the predicted state marginals ``(T, N, S)`` and the normalizers are stored;
    the local factors are recomputed during the backward pass.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}; got {method!r}")
    obs = np.asarray(obs)
    log_p0 = mdp.log_initial if log_initial is None else log_initial
    ids = np.arange(obs.shape[0]) if demo_ids is None else np.asarray(demo_ids)
    if method == "auto":
        stats = _scaled_forward_backward(mdp, log_policy, obs, log_emissions, log_p0)
        if stats is not None:
            return stats
    return log_forward_backward(
        mdp, log_policy, obs, log_emissions, log_initial=log_p0, demo_ids=ids
    )


def _scaled_floor(mdp: TabularMDP) -> float:
    """``F``: the scaled pass keeps local factors and predicted probabilities above ``e^-F``.

    Then ``alpha = pred * local >= e^-2F``, and pushed through ``T`` (entries at least
    ``t_min``) with normalizer at most ``S A``, it stays above ``e^-690``: nothing that is
    positive underflows to 0 (a float's smallest normal number is about ``e^-708``).
    """
    return (690.0 + mdp.min_log_transition - np.log(mdp.n_states * mdp.n_actions)) / 2.0


def _chunks(length: int, per_step: int) -> list[tuple[int, int]]:
    size = max(1, _CHUNK_ELEMENTS // max(per_step, 1))
    return [(t0, min(t0 + size, length)) for t0 in range(0, length, size)]


_CHUNK_ELEMENTS = 1 << 19


def _shifted_local(log_policy, obs, log_emissions, t0: int, t1: int, floor: float):
    """``exp(ll - max ll)`` of steps t0..t1-1, shape (N, t1 - t0, S, A), and the shifts
    ``max_{s, a} ll`` (N, t1 - t0); ``None`` if a positive factor falls below ``e^floor``."""
    ll = log_emissions[obs[:, t0:t1]]
    ll += log_policy if log_policy.ndim == 2 else log_policy[t0:t1]
    top = ll.max(axis=(2, 3))
    if not np.all(np.isfinite(top)):
        return None  # a step no pair can emit: the log-space pass names it
    ll -= top[:, :, None, None]
    low = ll < floor
    if low.any() and np.isfinite(ll[low]).any():
        return None
    return np.exp(ll, out=ll), top


def _scaled_forward_backward(mdp, log_policy, obs, log_emissions, log_p0):
    """The scaled pass; ``None`` when a message would leave its safe range (see module)."""
    n_demos, length = obs.shape
    S, A = mdp.n_states, mdp.n_actions
    F = _scaled_floor(mdp)
    if F < 20.0:
        return None
    chunks = _chunks(length, n_demos * S * A)

    preds = np.empty((length, n_demos, S))
    shifts = np.empty((length, n_demos))
    norms = np.empty((length, n_demos))
    pred = np.repeat(np.exp(log_p0)[None, :], n_demos, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        for t0, t1 in chunks:
            out = _shifted_local(log_policy, obs, log_emissions, t0, t1, -F)
            if out is None:
                return None
            local, shifts[t0:t1] = out[0], out[1].T
            for t in range(t0, t1):
                alpha = local[:, t - t0] * pred[:, :, None]
                c = alpha.sum(axis=(1, 2))
                preds[t], norms[t] = pred, c
                if t + 1 < length:
                    alpha /= c[:, None, None]
                    pred = _push_forward(mdp, alpha)
    if not np.all(norms > 0.0):
        return None  # impossible somewhere: the log-space pass names the demonstration
    if np.any((preds > 0.0) & (preds < np.exp(-F))):
        return None

    # beta_t(s, a) = sum_s' T(s, a, s') sum_a' pi(a'|s') e_{t+1}(s', a') beta_{t+1}(s', a'),
    # divided by c_{t+1} (Rabiner scaling), so that alpha_t * beta_t is the posterior
    # marginal of step t. The local factors carry the forward pass's shifts, so alpha_t and
    # beta_t are scaled consistently. A state the forward pass cannot reach at step t gets
    # g = 0: no pair with forward mass leads there, and so every beta stays below about e^F.
    occupancy = np.zeros((n_demos, S, A))
    beta = np.ones((n_demos, S, A))
    with np.errstate(over="ignore", invalid="ignore"):
        for t0, t1 in reversed(chunks):
            local = _shifted_local(log_policy, obs, log_emissions, t0, t1, -np.inf)[0]
            for t in range(t1 - 1, t0 - 1, -1):
                gamma_t = local[:, t - t0] * beta
                if t > 0:
                    g = gamma_t.sum(axis=2)  # (N, S)
                    g *= preds[t] > 0.0  # unreachable states send nothing back
                gamma_t *= (preds[t] / norms[t][:, None])[:, :, None]
                occupancy += gamma_t
                if t > 0:
                    beta = np.moveaxis(_expect_next(mdp, g.T), 2, 0)
                    beta /= norms[t][:, None, None]
    initial = gamma_t.sum(axis=2)
    if not (np.all(np.isfinite(occupancy)) and np.all(np.isfinite(initial))):
        return None
    return PosteriorStats(
        log_likelihood=shifts.sum(axis=0) + np.log(norms).sum(axis=0),
        occupancy=occupancy,
        initial=initial,
    )


def log_forward_backward(
    mdp: TabularMDP,
    log_policy: np.ndarray,
    obs: np.ndarray,
    log_emissions: np.ndarray,
    *,
    log_initial: np.ndarray | None = None,
    demo_ids: Sequence[int] | None = None,
) -> PosteriorStats:
    """Forward-backward with every message in log space: exact at any dynamic range.

    Arguments as :func:`forward_backward`. The messages are pushed through the transition
    operator with ``logsumexp`` over its positive entries (:meth:`TabularMDP.log_push_forward`,
    :meth:`TabularMDP.log_expect_next`), ``O(T nnz(T))`` exponentials per demonstration.
    """
    obs = np.asarray(obs)
    n_demos, length = obs.shape
    S, A = mdp.n_states, mdp.n_actions
    log_p0 = mdp.log_initial if log_initial is None else log_initial
    ids = np.arange(n_demos) if demo_ids is None else np.asarray(demo_ids)
    local = _local(log_policy, obs, log_emissions)

    log_preds = np.empty((length, n_demos, S))
    log_norms = np.empty((length, n_demos))
    lp = np.repeat(log_p0[None, :], n_demos, axis=0)
    for t in range(length):
        la = local(t)
        la += lp[:, :, None]
        lc = _logsumexp(la, axis=(1, 2))
        if not np.all(np.isfinite(lc)):
            raise _impossible(ids, obs, int(np.flatnonzero(~np.isfinite(lc))[0]), t)
        log_preds[t], log_norms[t] = lp, lc
        if t + 1 < length:
            la -= lc[:, None, None]
            lp = mdp.log_push_forward(la)

    occupancy = np.zeros((n_demos, S, A))
    log_beta = np.zeros((n_demos, S, A))
    for t in range(length - 1, -1, -1):
        lg = local(t)
        lg += log_beta  # log(pi e_t beta_t)
        log_post = lg + (log_preds[t] - log_norms[t][:, None])[:, :, None]
        post = np.exp(log_post)
        occupancy += post
        if t > 0:
            log_beta = mdp.log_expect_next(_logsumexp(lg, axis=2))
            log_beta -= log_norms[t][:, None, None]
    return PosteriorStats(
        log_likelihood=log_norms.sum(axis=0),
        occupancy=occupancy,
        initial=post.sum(axis=2),
    )


def posterior_stats(
    mdp: TabularMDP,
    log_policy: np.ndarray | None,
    demos: Sequence[Demonstration],
    observation_model,
    *,
    log_policies_by_length=None,
    method: str = "auto",
) -> PosteriorStats:
    """:func:`forward_backward` over demonstrations of any lengths, in length-batches.

    ``log_policy`` is a stationary ``log pi[s, a]``; alternatively ``log_policies_by_length(T)``
    returns a ``(T, S, A)`` log-policy for demonstrations of length T (finite-horizon models).
    """
    log_emissions = observation_model.log_emissions
    n = len(demos)
    ll = np.empty(n)
    occ = np.empty((n, mdp.n_states, mdp.n_actions))
    init = np.empty((n, mdp.n_states))
    for length, idx in group_by_length(demos).items():
        packed = pack_observations([demos[i] for i in idx], observation_model.n_observations)
        pol = log_policy if log_policies_by_length is None else log_policies_by_length(length)
        stats = forward_backward(mdp, pol, packed, log_emissions, demo_ids=idx, method=method)
        ll[idx], occ[idx], init[idx] = stats.log_likelihood, stats.occupancy, stats.initial
    return PosteriorStats(log_likelihood=ll, occupancy=occ, initial=init)


def _push_forward(mdp, mass):
    """The flat-operator product as it was: ``(P.T @ mass.T).T``."""
    lead = mass.shape[:-2]
    flat_mass = mass.reshape(-1, mdp.n_states * mdp.n_actions)
    out = (mdp._flat.T @ flat_mass.T).T
    return np.asarray(out).reshape((*lead, mdp.n_states))


def _expect_next(mdp, values):
    out = mdp._flat @ values
    return np.asarray(out).reshape((mdp.n_states, mdp.n_actions, *values.shape[1:]))


class _CheckedPrior(GaussianPrior):
    """The prior as the fit called it before: ``log_prob`` and ``grad_log_prob`` each
    validating theta at every optimizer step."""

    def _value_and_grad(self, n_features):
        return lambda theta: (self.log_prob(theta), self.grad_log_prob(theta))


# -- the planning kernels of e77f9cd (irl/solvers.py), frozen --------------------------

@dataclass(frozen=True)
class OptimalSolution:
    """The optimal policy of one reward and the derivatives of ``Q*`` in theta.

    Attributes
    ----------
    policy : ndarray of shape (S,)
        A deterministic optimal (greedy) policy.
    dQ : ndarray of shape (S, A, K)
        ``dQ*(s, a) / dtheta``; ``Q* = dQ @ theta`` inside this policy's optimality region.
    """

    policy: np.ndarray
    dQ: np.ndarray

    def q_values(self, theta: np.ndarray) -> np.ndarray:
        """``Q*[s, a]`` for a theta in this policy's optimality region."""
        return self.dQ @ theta


def greedy_policy(Q: np.ndarray) -> np.ndarray:
    """``argmax_a Q[s, a]`` (lowest action index on ties), shape (S,)."""
    return np.argmax(Q, axis=1)


def boltzmann_policy(Q: np.ndarray, beta: float) -> np.ndarray:
    """``pi[s, a] = softmax_a(beta * Q[s, a])``."""
    return np.exp(log_boltzmann_policy(Q, beta))


def log_boltzmann_policy(Q: np.ndarray, beta: float) -> np.ndarray:
    """``log pi[s, a]`` of the Boltzmann policy, computed stably."""
    return log_softmax(beta * Q, axis=1)


def _solve_policy_system(mdp: TabularMDP, policy: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve ``(I - gamma P_pi) X = rhs`` for a deterministic policy; rhs has shape (S, m)."""
    P = mdp.policy_transitions(policy)
    n = mdp.n_states
    if sp.issparse(P):
        A = (sp.identity(n, format="csc") - mdp.discount * P.tocsc()).tocsc()
        lu = spla.splu(A)
        return lu.solve(np.ascontiguousarray(rhs))
    return np.linalg.solve(np.eye(n) - mdp.discount * P, rhs)


def solve_policy_derivatives(mdp: TabularMDP, policy: np.ndarray) -> np.ndarray:
    """``dQ^pi[s, a, k]``: the Q-function of ``pi`` per unit of each feature weight.

    Solves ``dV = (I - gamma P_pi)^{-1} phi_pi`` (one factorization, K right-hand sides) and
    returns ``dQ = phi + gamma T dV``. For an optimal ``pi`` this is ``dQ*/dtheta``.
    """
    phi_pi = mdp.features[np.arange(mdp.n_states), policy]  # (S, K)
    dV = _solve_policy_system(mdp, policy, phi_pi)
    return mdp.features + mdp.discount * mdp.expect_next(dV)


def policy_values(mdp: TabularMDP, reward: np.ndarray, policy: np.ndarray) -> np.ndarray:
    """Exact values ``V^pi[s]`` of a deterministic policy under reward ``R[s, a]``."""
    r_pi = reward[np.arange(mdp.n_states), policy]
    return _solve_policy_system(mdp, policy, r_pi[:, None])[:, 0]


class OptimalQSolver:
    """Optimal Q-functions and ``dQ*/dtheta`` for one MDP, cached per greedy policy.

    Parameters
    ----------
    mdp : TabularMDP
    max_iter : int
        Maximum policy-iteration sweeps per solve.
    cache_size : int
        How many greedy policies (and their ``dQ``) to keep.
    warm_start_sweeps : int
        Value-iteration sweeps (one sparse product each) that pick the first policy of a solve
        with an empty cache; they save policy-iteration sweeps (one factorization each) on
        large MDPs.

    Attributes
    ----------
    n_solves_ : int
        Policy-iteration runs so far (cache misses).
    n_reuses_ : int
        Solves answered from a cached optimality region.
    """

    def __init__(
        self, mdp: TabularMDP, *, max_iter: int = 200, cache_size: int = 64,
        warm_start_sweeps: int = 200,
    ) -> None:
        self.mdp = mdp
        self.max_iter = max_iter
        self.warm_start_sweeps = warm_start_sweeps
        self.cache_size = cache_size
        self._cache: OrderedDict[bytes, OptimalSolution] = OrderedDict()
        self.n_solves_ = 0
        self.n_reuses_ = 0

    def solve(self, theta: np.ndarray) -> OptimalSolution:
        """The optimal policy and ``dQ*`` for reward ``phi . theta``."""
        theta = self.mdp.check_theta(theta)
        for key, sol in reversed(self._cache.items()):
            if self._in_region(sol, theta):
                self._cache.move_to_end(key)
                self.n_reuses_ += 1
                return sol
        start = next(reversed(self._cache.values())).policy if self._cache else None
        sol = self._policy_iteration(theta, start)
        self.n_solves_ += 1
        self._cache[sol.policy.tobytes()] = sol
        if len(self._cache) > self.cache_size:
            self._cache.popitem(last=False)
        return sol

    def q_values(self, theta: np.ndarray) -> np.ndarray:
        """``Q*[s, a]`` for reward ``phi . theta``."""
        theta = self.mdp.check_theta(theta)
        return self.solve(theta).q_values(theta)

    @staticmethod
    def _in_region(sol: OptimalSolution, theta: np.ndarray) -> bool:
        Q = sol.q_values(theta)
        chosen = Q[np.arange(Q.shape[0]), sol.policy]
        tol = _TIE_TOL * (1.0 + np.abs(Q).max())
        return bool(np.all(chosen >= Q.max(axis=1) - tol))

    def _policy_iteration(self, theta: np.ndarray, policy: np.ndarray | None) -> OptimalSolution:
        mdp = self.mdp
        reward = mdp.reward(theta)
        if policy is None:
            V = np.zeros(mdp.n_states)
            Q = reward
            for _ in range(self.warm_start_sweeps):
                V = Q.max(axis=1)
                Q = reward + mdp.discount * mdp.expect_next(V)
            policy = greedy_policy(Q)
        rows = np.arange(mdp.n_states)
        for _ in range(self.max_iter):
            dQ = solve_policy_derivatives(mdp, policy)
            Q = dQ @ theta
            best = greedy_policy(Q)
            tol = _TIE_TOL * (1.0 + np.abs(Q).max())
            improve = Q[rows, best] > Q[rows, policy] + tol
            if not improve.any():
                return OptimalSolution(policy=policy.copy(), dQ=dQ)
            policy = np.where(improve, best, policy)
        warnings.warn(
            f"policy iteration did not converge in max_iter={self.max_iter} sweeps",
            ConvergenceWarning,
            stacklevel=3,
        )
        return OptimalSolution(policy=policy.copy(), dQ=solve_policy_derivatives(mdp, policy))


class BaselineMMAPBIRL(MMAPBIRL):
    """MMAP-BIRL on the frozen path: demonstrations re-packed and emissions re-gathered from
    the dense table at every gradient, and the checked prior."""

    def _check_model(self):
        model = super()._check_model()
        prior = _CheckedPrior(model.prior.mean, model.prior.std)
        return type(model)(model.mdp, model.observation_model, model.beta, prior,
                           OptimalQSolver(model.mdp))

    @staticmethod
    def _log_policy(model, theta):
        sol = model.solver.solve(theta)
        return sol, log_softmax(model.beta * sol.q_values(theta), axis=1)

    def _likelihood_and_gradient(self, model, theta, data):
        sol, log_pi = self._log_policy(model, theta)
        ll, G = self._pair_stats(model, log_pi, data)
        pi = np.exp(log_pi)
        expected_dQ = np.einsum("sa,sak->sk", pi, sol.dQ)
        grad = model.beta * (
            np.einsum("sa,sak->k", G, sol.dQ) - np.einsum("s,sk->k", G.sum(axis=1), expected_dQ)
        )
        return ll, grad

    def _prepare(self, model, demos):
        return demos

    def _pair_stats(self, model, log_pi, demos):
        stats = posterior_stats(model.mdp, log_pi, demos, model.observation_model)
        return float(stats.log_likelihood.sum()), stats.occupancy.sum(axis=0)
