"""Planning kernels: optimal Q-functions, their derivatives in theta, Boltzmann policies.

Layouts: ``R[s, a]``, ``Q[s, a]``, ``dQ[s, a, k] = dQ*(s, a) / dtheta_k``, ``pi[s, a]``,
deterministic policies as ``policy[s] -> a``.

With a linear reward ``R = phi . theta`` and a fixed deterministic policy ``pi``, the value is
linear in theta: ``V^pi = (I - gamma P_pi)^{-1} phi_pi theta``. Hence for the optimal policy
``pi*`` of theta, ``Q* = dQ . theta`` with ``dQ = phi + gamma T (I - gamma P_pi*)^{-1} phi_pi*``
(Choi & Kim 2011). ``dQ`` depends on theta only through ``pi*``; :class:`OptimalQSolver` caches
it per greedy policy and reuses it for every theta in that policy's reward-optimality region
(``Q(s, pi*(s)) >= Q(s, a)`` for all s, a), which is the paper's gradient reuse.
"""

from __future__ import annotations

import logging
import warnings
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
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
