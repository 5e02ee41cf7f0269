"""Planning kernels: optimal Q-functions, their derivatives in theta, Boltzmann policies.

Layouts: ``R[s, a]``, ``Q[s, a]``, ``dQ[s, a, k] = dQ*(s, a) / dtheta_k``, ``pi[s, a]``,
deterministic policies as ``policy[s] -> a``.

With a linear reward ``R = phi . theta`` and a fixed deterministic policy ``pi``, the value is
linear in theta: ``V^pi = (I - gamma P_pi)^{-1} phi_pi theta``. Hence for the optimal policy
``pi*`` of theta, ``Q* = dQ . theta`` with ``dQ = phi + gamma T (I - gamma P_pi*)^{-1} phi_pi*``
(Choi & Kim 2011). ``dQ`` depends on theta only through ``pi*``; :class:`OptimalQSolver` caches
it per greedy policy and reuses it for every theta in that policy's reward-optimality region
(``Q(s, pi*(s)) >= Q(s, a)`` for all s, a), which is the paper's gradient reuse.

A solve that misses the cache runs policy iteration with value-iteration sweeps around its
evaluations (a sweep is one product with T). A cold one (empty cache) starts from the greedy
policy of up to ``warm_start_sweeps`` sweeps from ``V = max_a R``; any other from the last
cached policy. Each evaluation factors ``I - gamma P_pi`` once and solves for ``V^pi`` (one
right-hand side). If some state's greedy action beats the policy's by more than the tie
tolerance, up to ``improvement_sweeps`` sweeps from ``T V^pi`` pick the next policy, starting
from Howard's improved one: value iteration from exact values settles much faster than from
``V = max_a R``, and as long as a factorization costs more than the sweeps, they save
evaluations. Otherwise ``dV`` is solved for (K right-hand sides) with the same factorization.
Both runs of sweeps stop once the policy they follow has held for ``sweep_patience`` sweeps.
Since ``T V^pi >= V^pi``, the sweeps' values only grow from ``T V^pi`` and the next policy is
greedy for them, so its values are at least ``T V^pi``, as Howard's are: every evaluation still
improves on the last, and the solve ends, as before, at a policy that no state can improve.
Ties: a policy's action is replaced only by one better by more than the tolerance (the
lowest-index one); the warm start hands over the lowest-index greedy policy.

``I - gamma P_pi`` is strictly row diagonally dominant (margin ``1 - gamma``), so its sparse LU
needs no pivoting: SuperLU factors it in symmetric mode on diagonal pivots with a minimum-degree
ordering of ``A + A^T`` (less fill than its default column ordering on grid-like MDPs), and the
ordering is reused while the sparsity pattern of ``P_pi`` repeats.
"""

from __future__ import annotations

import logging
import warnings
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.special import log_softmax

from irl.exceptions import ConvergenceWarning
from irl.mdp import TabularMDP

__all__ = [
    "OptimalQSolver",
    "OptimalSolution",
    "boltzmann_policy",
    "greedy_policy",
    "log_boltzmann_policy",
    "policy_values",
    "solve_policy_derivatives",
]

logger = logging.getLogger(__name__)

_TIE_TOL = 1e-10


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
    """``log pi[s, a]`` of the Boltzmann policy, computed stably (``log_softmax`` over the
    actions, one column at a time: numpy reduces a short contiguous axis slowly, and the
    learners call this at every gradient)."""
    Q = np.asarray(Q, dtype=float)
    if Q.ndim != 2:
        return log_softmax(beta * Q, axis=1)
    z = np.multiply(Q, beta)
    z -= _row_max(z)[:, None]
    e = np.exp(z)
    total = e[:, 0].copy()
    for a in range(1, e.shape[1]):
        total += e[:, a]
    z -= np.log(total)[:, None]
    return z


class _PolicySystem:
    """Factorizations of ``I - gamma P_pi`` for the deterministic policies of one MDP.

    Sparse LU runs without pivoting (diagonal pivots, SuperLU's symmetric mode), which is stable
    here: the matrix is strictly row diagonally dominant with margin ``1 - gamma``, a property
    that symmetric permutations and Gaussian elimination preserve (growth factor at most 2).
    The fill-reducing ordering (minimum degree on ``A + A^T``) of the first factorization is
    kept with the sparsity pattern it was computed for; a later matrix with the same pattern
    is permuted by it and factored in natural order, which skips the ordering step.
    """

    def __init__(self, mdp: TabularMDP) -> None:
        self.mdp = mdp
        #: The last factorization's cost in value-iteration sweeps, roughly (from its fill).
        self.sweep_equivalent = 0.0
        self._pattern: tuple[np.ndarray, np.ndarray] | None = None
        self._order: np.ndarray | None = None  # A[order][:, order] is factored in natural order

    def factor(self, policy: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        """``rhs -> (I - gamma P_pi)^{-1} rhs`` for rhs of shape (S, m), from one factorization."""
        mdp = self.mdp
        n = mdp.n_states
        P = mdp.policy_transitions(policy)
        if not sp.issparse(P):
            lu = sla.lu_factor(np.eye(n) - mdp.discount * P, check_finite=False)
            self.sweep_equivalent = n / (3 * mdp.n_actions)  # 2 S^3 / 3 flops vs 2 S A S
            return lambda rhs: sla.lu_solve(lu, rhs, check_finite=False)
        A = (sp.identity(n, format="csc") - mdp.discount * P.tocsc()).tocsc()
        A.sort_indices()
        # panel_size=1: SuperLU's default panels of 10 columns were 20-30% slower on grid
        # MDPs from 900 to 100,000 states (the same factors; supernodes are narrow here)
        opts = {"diag_pivot_thresh": 0.0, "panel_size": 1, "options": {"SymmetricMode": True}}
        pattern = self._pattern
        if pattern is not None and np.array_equal(A.indptr, pattern[0]) \
                and np.array_equal(A.indices, pattern[1]):
            order = self._order
            lu = spla.splu(A[order][:, order].tocsc(), permc_spec="NATURAL", **opts)
            self._note_cost(lu, P)

            def solve(rhs: np.ndarray) -> np.ndarray:
                out = np.empty(rhs.shape)
                out[order] = lu.solve(np.ascontiguousarray(rhs[order]))
                return out

            return solve
        lu = spla.splu(A, permc_spec="MMD_AT_PLUS_A", **opts)
        self._note_cost(lu, P)
        order = np.empty(n, dtype=np.intp)
        order[lu.perm_c] = np.arange(n)
        self._pattern, self._order = (A.indptr.copy(), A.indices.copy()), order
        return lambda rhs: lu.solve(np.ascontiguousarray(rhs))

    def _note_cost(self, lu: spla.SuperLU, P: sp.csr_matrix) -> None:
        # A factorization's flops are about S c^2 for c = nnz(L + U) / S entries per column;
        # a value-iteration sweep reads the A nnz(P_pi) (or so) entries of T.
        self.sweep_equivalent = lu.nnz ** 2 / self.mdp.n_states / max(
            1, self.mdp.n_actions * P.nnz)


def _solve_policy_system(mdp: TabularMDP, policy: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve ``(I - gamma P_pi) X = rhs`` for a deterministic policy; rhs has shape (S, m)."""
    return _PolicySystem(mdp).factor(policy)(rhs)


def _derivatives(mdp: TabularMDP, policy: np.ndarray,
                 solve: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """``dQ^pi = phi + gamma T (I - gamma P_pi)^{-1} phi_pi`` with a factored system."""
    phi_pi = mdp.features[np.arange(mdp.n_states), policy]  # (S, K)
    return mdp.features + mdp.discount * mdp.expect_next(solve(phi_pi))


def solve_policy_derivatives(mdp: TabularMDP, policy: np.ndarray) -> np.ndarray:
    """``dQ^pi[s, a, k]``: the Q-function of ``pi`` per unit of each feature weight.

    Solves ``dV = (I - gamma P_pi)^{-1} phi_pi`` (one factorization, K right-hand sides) and
    returns ``dQ = phi + gamma T dV``. For an optimal ``pi`` this is ``dQ*/dtheta``.
    """
    return _derivatives(mdp, policy, _PolicySystem(mdp).factor(policy))


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
        Maximum policy evaluations (factorizations) per solve.
    cache_size : int
        How many greedy policies (and their ``dQ``) to keep.
    warm_start_sweeps : int
        At most this many value-iteration sweeps (one product with T each) pick the first
        policy of a solve with an empty cache; they save policy evaluations (one factorization
        each) on large MDPs.
    sweep_patience : int or None
        Value iteration (the warm start's, and the sweeps after an evaluation) stops once the
        policy it follows has held for this many consecutive sweeps; None never stops early.
    improvement_sweeps : int
        At most this many value-iteration sweeps, from an evaluated policy's exact values,
        choose the next policy to evaluate; fewer where a factorization costs fewer sweeps
        (estimated from its fill), none where it costs fewer than ``sweep_patience`` (a small
        dense MDP, where Howard's step is as cheap). 0 gives Howard's policy iteration.

        These options change how many sweeps and factorizations a solve takes, never its
        result's optimality; on exact ties (within the tolerance) they can change which of
        several optimal policies is returned.

    Attributes
    ----------
    n_solves_ : int
        Policy-iteration runs so far (cache misses).
    n_reuses_ : int
        Solves answered from a cached optimality region.
    """

    def __init__(
        self, mdp: TabularMDP, *, max_iter: int = 200, cache_size: int = 64,
        warm_start_sweeps: int = 100, sweep_patience: int | None = 10,
        improvement_sweeps: int = 100,
    ) -> None:
        self.mdp = mdp
        self.max_iter = max_iter
        self.warm_start_sweeps = warm_start_sweeps
        self.sweep_patience = sweep_patience
        self.improvement_sweeps = improvement_sweeps
        self.cache_size = cache_size
        self._system = _PolicySystem(mdp)
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
        return bool((chosen >= _row_max(Q) - tol).all())

    def _value_iteration(self, reward: np.ndarray, Q: np.ndarray, policy: np.ndarray,
                         max_sweeps: int) -> tuple[np.ndarray, np.ndarray, int]:
        """Up to ``max_sweeps`` sweeps ``Q <- R + gamma T max_a Q`` from ``Q``, stopped once
        the followed policy has held for ``sweep_patience`` sweeps.

        ``policy`` (updated in place) follows the greedy actions: a state's action is replaced
        (by the lowest-index maximizer) only where it falls short of the maximum by more than
        the tie tolerance, which is also cheaper than an ``argmax`` per sweep. Returns the last
        ``Q``, the policy and the number of sweeps.
        """
        mdp = self.mdp
        n, n_actions = reward.shape
        row_start = np.arange(n) * n_actions
        patience = self.sweep_patience
        # |V| <= max |R| / (1 - gamma) along value iteration from V = max_a R.
        tol = _TIE_TOL * (1.0 + np.abs(Q).max() + np.abs(reward).max() / (1.0 - mdp.discount))
        V = _row_max(Q)
        buf = np.empty_like(reward)
        stable = sweep = 0
        while sweep < max_sweeps:
            sweep += 1
            Q = np.multiply(mdp.expect_next(V), mdp.discount, out=buf)
            Q += reward
            chosen = Q.ravel()[row_start + policy]
            V = _row_max(Q)
            moved = chosen < V - tol
            if moved.any():
                moved = np.flatnonzero(moved)
                policy[moved] = greedy_policy(Q[moved])
                stable = 0
            else:
                stable += 1
                if patience is not None and stable >= patience:
                    break
        return Q, policy, sweep

    def _policy_iteration(self, theta: np.ndarray, policy: np.ndarray | None) -> OptimalSolution:
        mdp = self.mdp
        reward = mdp.reward(theta)
        n_sweeps = 0
        if policy is None:
            Q, _, n_sweeps = self._value_iteration(reward, reward, greedy_policy(reward),
                                                   self.warm_start_sweeps)
            policy = greedy_policy(Q)
        rows = np.arange(mdp.n_states)
        for it in range(self.max_iter):
            solve = self._system.factor(policy)
            V = solve(reward[rows, policy][:, None])[:, 0]
            Q = reward + mdp.discount * mdp.expect_next(V)
            improve, best = _improvable(Q, policy)
            if not improve.any():
                # The derivatives from the same factorization; their Q decides again (it
                # differs from the one above by rounding only).
                dQ = _derivatives(mdp, policy, solve)
                improve, best = _improvable(dQ @ theta, policy)
                if not improve.any():
                    logger.debug("policy iteration: %d value-iteration sweeps, %d evaluations",
                                 n_sweeps, it + 1)
                    return OptimalSolution(policy=policy.copy(), dQ=dQ)
            policy = np.where(improve, best, policy)
            # Sweeps pay where a factorization costs at least enough of them for the policy to
            # settle (sweep_patience); on a small dense MDP it costs a few.
            budget = min(self.improvement_sweeps, int(self._system.sweep_equivalent))
            if budget > 0 and budget >= (self.sweep_patience or 0):
                _, policy, k = self._value_iteration(reward, Q, policy, budget)
                n_sweeps += k
        warnings.warn(
            f"policy iteration did not converge in max_iter={self.max_iter} evaluations",
            ConvergenceWarning,
            stacklevel=3,
        )
        return OptimalSolution(policy=policy.copy(),
                               dQ=_derivatives(mdp, policy, self._system.factor(policy)))


def _improvable(Q: np.ndarray, policy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """States where the greedy action of ``Q`` beats ``policy`` by more than the tie tolerance,
    and the greedy actions (lowest index on ties)."""
    best = greedy_policy(Q)
    rows = np.arange(Q.shape[0])
    tol = _TIE_TOL * (1.0 + np.abs(Q).max())
    return Q[rows, best] > Q[rows, policy] + tol, best


def _row_max(Q: np.ndarray) -> np.ndarray:
    """``Q.max(axis=1)`` of an (S, A) array, one column at a time (numpy reduces a short
    contiguous axis slowly)."""
    out = Q[:, 0].copy()
    for a in range(1, Q.shape[1]):
        np.maximum(out, Q[:, a], out=out)
    return out
