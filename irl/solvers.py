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

On sparse MDPs of at least ``krylov_min_states`` states a policy is evaluated by BiCGSTAB
instead, from the last values as the guess, with products by ``P_pi`` only: the LU's fill grows
faster than S on grids (``bench/bench_irl.py`` times both at each size in [3]). Those
evaluations stop at a relative residual of ``krylov_tol``, which only steers the iteration: the
policy that no state improves on is checked again on exact values. Its derivatives ``dV`` (one
right-hand side per feature) come from BiCGSTAB solved to a true residual that bounds their
error below 1e-12 of their size, or from one factorization where that is predicted to cost
fewer sweeps, from the slowest convergence rate seen; an iteration that does not converge in
``krylov_max_iter`` falls back to factoring. A near-optimal policy that an inexact evaluation
called final, and its exact check did not, makes the rest of that solve's evaluations exact, as
does a policy evaluated twice (an inexact evaluation can make a near-tie look improvable), so
the solve ends as exact policy iteration does.
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

from irl._blas import one_blas_thread
from irl._validation import check_int, check_real, describe
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
#: Relative error (max norm) to which BiCGSTAB solves the last policy's derivatives.
_EXACT_ERROR = 1e-12
#: A factorization's cost in value-iteration sweeps assumed before the first one (about
#: that of a 100 x 100 grid's): BiCGSTAB computes the last derivatives where it costs less.
_FACTOR_SWEEPS = 100.0


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
    """``argmax_a Q[s, a]`` (lowest action index on ties).

    Parameters
    ----------
    Q : ndarray of shape (S, A)

    Returns
    -------
    ndarray of int, shape (S,)
        ``policy[s] -> a``.
    """
    return np.argmax(Q, axis=1)


def boltzmann_policy(Q: np.ndarray, beta: float) -> np.ndarray:
    """``pi[s, a] = softmax_a(beta * Q[s, a])``.

    Parameters
    ----------
    Q : ndarray of shape (S, A)
    beta : float
        The rationality: 0 is uniform, larger is greedier.

    Returns
    -------
    ndarray of shape (S, A)
        Each row sums to 1.
    """
    return np.exp(log_boltzmann_policy(Q, beta))


def log_boltzmann_policy(Q: np.ndarray, beta: float) -> np.ndarray:
    """``log pi[s, a]`` of the Boltzmann policy, computed stably (``log_softmax`` over the
    actions, one column at a time: numpy reduces a short contiguous axis slowly, and the
    learners call this at every gradient).

    Parameters
    ----------
    Q : ndarray of shape (S, A)
        (Any other shape: the softmax is over its axis 1.)
    beta : float

    Returns
    -------
    ndarray of the shape of ``Q``
        Finite wherever ``beta * Q`` is; ``logsumexp`` over the actions is 0.
    """
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


def _policy_operator(mdp: TabularMDP, policy: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """``x -> (I - gamma P_pi) x`` for x of shape (S,) or (S, m), one product with the sparse
    ``P_pi`` of a deterministic policy."""
    P = mdp.policy_transitions(policy)
    P = sp.csr_matrix((P.data * -mdp.discount, P.indices, P.indptr), shape=P.shape)

    def matvec(x: np.ndarray) -> np.ndarray:
        y = P @ x
        y += x
        return y

    return matvec


def _bicgstab(matvec: Callable[[np.ndarray], np.ndarray], b: np.ndarray, x: np.ndarray,
              tol: float, max_iter: int) -> tuple[np.ndarray | None, int, float]:
    """Unpreconditioned BiCGSTAB (van der Vorst 1992) for ``A x = b`` from the guess ``x``.

    Stops once the recurred residual has ``||r||_2 <= tol``. Returns the solution (None where
    it did not get there in ``max_iter`` iterations or broke down on a zero inner product),
    the number of iterations (two products with ``A`` each) and the convergence rate, ``log
    ||r||_2 / ||r_0||_2`` per iteration (0 where no iteration ran).
    """
    x = x.copy()
    r = b - matvec(x)
    start = rr = r @ r
    r_hat = r.copy()
    p = r.copy()
    rho = rr
    it = 0
    while rr > tol * tol and it < max_iter:
        it += 1
        v = matvec(p)
        denom = r_hat @ v
        if rho == 0.0 or denom == 0.0:
            return None, it, 0.0
        alpha = rho / denom
        x += alpha * p
        r -= alpha * v  # s in the usual notation
        t = matvec(r)
        tt = t @ t
        omega = (t @ r) / tt if tt > 0.0 else 0.0
        x += omega * r
        r -= omega * t
        rr = r @ r
        if rr <= tol * tol:
            break
        if omega == 0.0:
            return None, it, 0.0
        rho_next = r_hat @ r
        p -= omega * v
        p *= (rho_next / rho) * (alpha / omega)
        p += r
        rho = rho_next
    rate = np.log(rr / start) / (2 * it) if it and rr > 0.0 else 0.0
    return (x if rr <= tol * tol else None), it, rate


def _derivatives(mdp: TabularMDP, policy: np.ndarray,
                 solve: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """``dQ^pi = phi + gamma T (I - gamma P_pi)^{-1} phi_pi`` with a factored system."""
    phi_pi = mdp.features[np.arange(mdp.n_states), policy]  # (S, K)
    return mdp.features + mdp.discount * mdp.expect_next(solve(phi_pi))


def solve_policy_derivatives(mdp: TabularMDP, policy: np.ndarray) -> np.ndarray:
    """``dQ^pi[s, a, k]``: the Q-function of ``pi`` per unit of each feature weight.

    Solves ``dV = (I - gamma P_pi)^{-1} phi_pi`` (one factorization, K right-hand sides) and
    returns ``dQ = phi + gamma T dV``. For an optimal ``pi`` this is ``dQ*/dtheta``.

    Parameters
    ----------
    mdp : TabularMDP
    policy : ndarray of int, shape (S,)
        A deterministic policy.

    Returns
    -------
    ndarray of shape (S, A, K)
        ``dQ``; ``dQ @ theta`` is ``Q^pi`` under the reward of ``theta``.
    """
    return _derivatives(mdp, policy, _PolicySystem(mdp).factor(policy))


def policy_values(mdp: TabularMDP, reward: np.ndarray, policy: np.ndarray) -> np.ndarray:
    """Exact values ``V^pi[s]`` of a deterministic policy under reward ``R[s, a]``.

    Parameters
    ----------
    mdp : TabularMDP
    reward : ndarray of shape (S, A)
        ``R[s, a]``, e.g. ``mdp.reward(theta)``.
    policy : ndarray of int, shape (S,)

    Returns
    -------
    ndarray of shape (S,)
        The discounted value of following ``policy`` from each state.
    """
    r_pi = reward[np.arange(mdp.n_states), policy]
    return _solve_policy_system(mdp, policy, r_pi[:, None])[:, 0]


class OptimalQSolver:
    """Optimal Q-functions and ``dQ*/dtheta`` for one MDP, cached per greedy policy.

    Parameters
    ----------
    mdp : TabularMDP
    max_iter : int
        Maximum policy evaluations per solve.
    cache_size : int
        How many greedy policies (and their ``dQ``) to keep.
    warm_start_sweeps : int
        At most this many value-iteration sweeps (one product with T each) pick the first
        policy of a solve with an empty cache; they save policy evaluations on large MDPs.
    sweep_patience : int or None
        Value iteration (the warm start's, and the sweeps after an evaluation) stops once the
        policy it follows has held for this many consecutive sweeps; None never stops early.
    improvement_sweeps : int
        At most this many value-iteration sweeps, from an evaluated policy's values, choose
        the next policy to evaluate; fewer where an evaluation costs fewer sweeps (a
        factorization's cost is estimated from its fill, BiCGSTAB's from its iterations),
        none where it costs fewer than ``sweep_patience`` (a small dense MDP, where Howard's
        step is as cheap). 0 gives Howard's policy iteration.
    krylov_min_states : int or None
        Sparse MDPs with at least this many states evaluate policies by BiCGSTAB (products
        with ``P_pi`` only) rather than by a sparse LU factorization, whose cost grows faster
        than S on grid-like MDPs; None always factors. See the module docstring.
    krylov_tol : float
        Relative residual (2-norm) at which BiCGSTAB stops on a policy that is not known to
        be the last; the last one's derivatives are always exact (to about 1e-12).
    krylov_max_iter : int
        BiCGSTAB iterations per solve of one right-hand side; a solve that does not converge
        in them falls back to a factorization, as do the rest of that policy iteration.

        These options change how a solve gets to its result, never the result's optimality;
        on exact ties (within the tolerance) they can change which of several optimal
        policies is returned.

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
        improvement_sweeps: int = 100, krylov_min_states: int | None = 1000,
        krylov_tol: float = 1e-6, krylov_max_iter: int = 1000,
    ) -> None:
        if not isinstance(mdp, TabularMDP):
            raise TypeError(f"mdp must be a TabularMDP; got {describe(mdp)}")
        self.mdp = mdp
        self.max_iter = check_int(max_iter, "max_iter", low=1)
        self.warm_start_sweeps = check_int(warm_start_sweeps, "warm_start_sweeps", low=0)
        self.sweep_patience = None if sweep_patience is None else check_int(
            sweep_patience, "sweep_patience", low=1)
        self.improvement_sweeps = check_int(improvement_sweeps, "improvement_sweeps", low=0)
        self.krylov_min_states = None if krylov_min_states is None else check_int(
            krylov_min_states, "krylov_min_states", low=1)
        self.krylov_tol = check_real(krylov_tol, "krylov_tol", low=0.0, high=1.0,
                                     low_open=True, high_open=True)
        self.krylov_max_iter = check_int(krylov_max_iter, "krylov_max_iter", low=1)
        self.cache_size = check_int(cache_size, "cache_size", low=1)
        self._system = _PolicySystem(mdp)
        #: The last evaluation's cost in value-iteration sweeps, roughly.
        self._evaluation_sweeps = 0.0
        #: The slowest BiCGSTAB convergence seen (log residual reduction per iteration).
        self._krylov_rate = 0.0
        #: What the current policy iteration has done, for its debug log.
        self._counts = {"sweeps": 0, "iterations": 0, "factorizations": 0}
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
        start = next(reversed(self._cache.values())) if self._cache else None
        with one_blas_thread(self.mdp.n_states * self.mdp.n_actions):
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

    def _policy_iteration(self, theta: np.ndarray,
                          start: OptimalSolution | None) -> OptimalSolution:
        """Policy iteration from the warm start's policy, or from the cached ``start``."""
        mdp = self.mdp
        reward = mdp.reward(theta)
        rows = np.arange(mdp.n_states)
        iterative = mdp.is_sparse and self.krylov_min_states is not None \
            and mdp.n_states >= self.krylov_min_states
        # Whether iterative evaluations must be exact: once a final check failed, or a policy
        # came back (an inexact evaluation's error can make a near-tie look improvable).
        exact = False
        evaluated: set[int] = set()
        self._counts = counts = dict.fromkeys(self._counts, 0)
        if start is None:
            Q, _, counts["sweeps"] = self._value_iteration(
                reward, reward, greedy_policy(reward), self.warm_start_sweeps)
            policy = greedy_policy(Q)
            V, Q = Q[rows, policy], None
        else:
            # The start's dQ gives its exact Q for this theta: no evaluation.
            policy, Q = start.policy.copy(), start.q_values(theta)
        for _ in range(self.max_iter):
            solve = operator = None
            if Q is None:
                r_pi = reward[rows, policy]
                if iterative and not exact:
                    key = hash(policy.tobytes())
                    exact = key in evaluated
                    evaluated.add(key)
                if iterative:
                    operator = _policy_operator(mdp, policy)
                    tol = self._exact_tol(r_pi) if exact \
                        else self.krylov_tol * np.sqrt(r_pi @ r_pi)
                    V = self._iterate(operator, r_pi, V, tol)
                    iterative = V is not None
                if not iterative:
                    solve = self._factor(policy)
                    V = solve(r_pi[:, None])[:, 0]
                Q = reward + mdp.discount * mdp.expect_next(V)
            improve, best = _improvable(Q, policy)
            if not improve.any():
                dQ = None
                if solve is None and iterative and self._iteration_pays(policy):
                    dQ = self._iterative_derivatives(
                        operator or _policy_operator(mdp, policy), policy)
                if dQ is None:
                    # The derivatives from one factorization (that of the values above where
                    # they were factored); their Q decides again: it differs from the one
                    # above by rounding, or by the iterative evaluation's error.
                    dQ = _derivatives(mdp, policy, solve or self._factor(policy))
                improve, best = _improvable(dQ @ theta, policy)
                if not improve.any():
                    logger.debug("policy iteration: %(sweeps)d value-iteration sweeps, "
                                 "%(iterations)d BiCGSTAB iterations, %(factorizations)d "
                                 "factorizations", counts)
                    return OptimalSolution(policy=policy.copy(), dQ=dQ)
                exact = True
            policy = np.where(improve, best, policy)
            # Sweeps pay where an evaluation costs at least enough of them for the policy to
            # settle (sweep_patience); on a small dense MDP it costs a few.
            budget = min(self.improvement_sweeps, int(self._evaluation_sweeps))
            if budget > 0 and budget >= (self.sweep_patience or 0):
                Q, policy, k = self._value_iteration(reward, Q, policy, budget)
                counts["sweeps"] += k
            V, Q = Q[rows, policy], None
        warnings.warn(
            f"policy iteration did not converge in max_iter={self.max_iter} evaluations",
            ConvergenceWarning,
            stacklevel=3,
        )
        return OptimalSolution(policy=policy.copy(),
                               dQ=_derivatives(mdp, policy, self._factor(policy)))

    def _factor(self, policy: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        solve = self._system.factor(policy)
        self._counts["factorizations"] += 1
        self._evaluation_sweeps = self._system.sweep_equivalent
        return solve

    def _exact_tol(self, b: np.ndarray) -> float:
        """A 2-norm residual small enough for ``(I - gamma P_pi) x = b`` to be solved to a
        relative error of ``_EXACT_ERROR`` in the max norm.

        ``||x - x*||_inf <= ||r||_inf / (1 - gamma) <= ||r||_2 / (1 - gamma)``, and
        ``||x*||_inf >= ||b||_inf / (1 + gamma)``.
        """
        gamma = self.mdp.discount
        return _EXACT_ERROR * (1.0 - gamma) / (1.0 + gamma) * np.abs(b).max()

    def _iterate(self, operator: Callable[[np.ndarray], np.ndarray], b: np.ndarray,
                 guess: np.ndarray, tol: float) -> np.ndarray | None:
        """BiCGSTAB for ``(I - gamma P_pi) x = b`` from ``guess``; None if it fails."""
        x, k, rate = _bicgstab(operator, b, guess, tol, self.krylov_max_iter)
        self._counts["iterations"] += k
        # an iteration's two products with P_pi read about 2 / A of T's entries
        self._evaluation_sweeps = 2 * k / self.mdp.n_actions
        if x is not None and k:
            self._krylov_rate = max(self._krylov_rate, rate) if self._krylov_rate else rate
        if x is None:
            logger.debug("BiCGSTAB did not converge in %d iterations: factoring", k)
        return x

    def _iteration_pays(self, policy: np.ndarray) -> bool:
        """Whether the last policy's exact derivatives (K right-hand sides) are predicted to
        cost BiCGSTAB fewer sweeps than a factorization (the last one's estimated cost, or
        ``_FACTOR_SWEEPS`` before any), at the slowest convergence rate seen."""
        rate = self._krylov_rate
        if rate >= 0.0:
            return False
        phi_pi = self.mdp.features[np.arange(self.mdp.n_states), policy]
        n_iter = 0.0
        for b in phi_pi.T:
            norm = np.sqrt(b @ b)
            if norm > 0.0:
                n_iter += max(0.0, np.log(self._exact_tol(b) / norm) / rate)
        factor_sweeps = self._system.sweep_equivalent or _FACTOR_SWEEPS
        return 2 * n_iter / self.mdp.n_actions < factor_sweeps

    def _iterative_derivatives(self, operator: Callable[[np.ndarray], np.ndarray],
                               policy: np.ndarray) -> np.ndarray | None:
        """``dQ^pi`` from BiCGSTAB solves of ``dV`` (one per feature), each to a true residual
        that bounds its error below ``_EXACT_ERROR`` (relative, max norm); None where one
        does not get there.

        BiCGSTAB's recurred residual drifts from the true one near rounding level, so a solve
        that stops short of the bound is restarted once from its solution (on the true
        residual).
        """
        mdp = self.mdp
        phi_pi = mdp.features[np.arange(mdp.n_states), policy]
        dV = np.empty(phi_pi.shape)
        for k, b in enumerate(np.ascontiguousarray(phi_pi.T)):
            x = np.zeros_like(b)
            for _ in range(2):
                x = self._iterate(operator, b, x, self._exact_tol(b))
                if x is None:
                    return None
                # ||x - x*||_inf <= ||b - A x||_inf / (1 - gamma)
                bound = _EXACT_ERROR * (1.0 - mdp.discount) * np.abs(x).max()
                if np.abs(b - operator(x)).max() <= bound:
                    break
            else:
                logger.debug("BiCGSTAB's derivatives missed their error bound: factoring")
                return None
            dV[:, k] = x
        return mdp.features + mdp.discount * mdp.expect_next(dV)


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
