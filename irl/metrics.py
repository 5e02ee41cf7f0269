"""How well a learned reward reproduces the expert: ILE and friends.

Layouts: ``V[s]``, deterministic policies ``policy[s] -> a``.
"""

from __future__ import annotations

import numpy as np

from irl._validation import as_float_array, as_index_array
from irl.mdp import TabularMDP
from irl.solvers import OptimalQSolver, policy_values

__all__ = [
    "inverse_learning_error",
    "normalized_inverse_learning_error",
    "policy_mismatch",
    "reward_distance",
]


def _check(mdp, true_theta, learned_theta) -> tuple[np.ndarray, np.ndarray]:
    if not isinstance(mdp, TabularMDP):
        raise TypeError(f"mdp must be an irl.TabularMDP; got {type(mdp).__name__}")
    return mdp.check_theta(true_theta, "true_theta"), mdp.check_theta(learned_theta,
                                                                      "learned_theta")


def _expert_and_learned_values(mdp: TabularMDP, true_theta, learned_theta):
    true_theta, learned_theta = _check(mdp, true_theta, learned_theta)
    solver = OptimalQSolver(mdp)
    pi_e = solver.solve(true_theta).policy
    pi_l = solver.solve(learned_theta).policy
    reward = mdp.reward(true_theta)
    return policy_values(mdp, reward, pi_e), policy_values(mdp, reward, pi_l)


def inverse_learning_error(mdp: TabularMDP, true_theta, learned_theta) -> float:
    """The paper's ILE: ``sum_s |V^{pi_E}(s) - V^{pi_L}(s)|``.

    ``pi_E`` and ``pi_L`` are greedy optimal for the true and the learned reward; both are
    evaluated under the true reward. Zero when the learned reward induces an optimal policy.
    """
    v_e, v_l = _expert_and_learned_values(mdp, true_theta, learned_theta)
    return float(np.abs(v_e - v_l).sum())


def normalized_inverse_learning_error(mdp: TabularMDP, true_theta, learned_theta) -> float:
    """ILE in percent of the expert's value: ``100 ||V_E - V_L||_1 / ||V_E||_1``."""
    v_e, v_l = _expert_and_learned_values(mdp, true_theta, learned_theta)
    return float(100.0 * np.abs(v_e - v_l).sum() / max(np.abs(v_e).sum(), 1e-300))


def policy_mismatch(mdp: TabularMDP, true_theta, learned_theta, states=None) -> float:
    """Fraction of states (or of ``states``) where the learned greedy action is not optimal.

    An action counts as optimal if its true ``Q*`` is within 1e-9 of the best (ties allowed).
    """
    true_theta, learned_theta = _check(mdp, true_theta, learned_theta)
    idx = (np.arange(mdp.n_states) if states is None
           else as_index_array(states, "states", size=mdp.n_states))
    solver = OptimalQSolver(mdp)
    Q = solver.q_values(true_theta)
    pi_l = solver.solve(learned_theta).policy
    tol = 1e-9 * (1.0 + np.abs(Q).max())
    wrong = Q[idx, pi_l[idx]] < Q[idx].max(axis=1) - tol
    return float(wrong.mean())


def reward_distance(true_theta, learned_theta) -> float:
    """Euclidean distance between unit-normalized weight vectors (the scale of a reward is not
    identifiable from behaviour), in [0, 2]."""
    a = as_float_array(true_theta, "true_theta", ndim=1)
    b = as_float_array(learned_theta, "learned_theta", ndim=1)
    if a.shape != b.shape:
        raise ValueError(
            f"learned_theta must have the shape of true_theta {a.shape}; got {b.shape}"
        )
    for name, v in (("true_theta", a), ("learned_theta", b)):
        if not np.any(v):
            raise ValueError(f"{name} must not be all zeros (reward_distance is undefined)")
    a, b = a / np.abs(a).max(), b / np.abs(b).max()  # no overflow in the norms
    return float(np.linalg.norm(a / np.linalg.norm(a) - b / np.linalg.norm(b)))
