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


def _check_learned(mdp, true_theta, learned_theta, policy):
    """``(true_theta, learned_theta or None, policy or None)`` checked: exactly one of
    ``learned_theta`` (a reward, whose greedy policy is scored) and ``policy[s]`` (a learner
    with no reward, such as behaviour cloning) is given."""
    if (learned_theta is None) == (policy is None):
        raise ValueError("give exactly one of learned_theta and policy; got "
                         + ("neither" if policy is None else "both"))
    if policy is None:
        return (*_check(mdp, true_theta, learned_theta), None)
    if not isinstance(mdp, TabularMDP):
        raise TypeError(f"mdp must be an irl.TabularMDP; got {type(mdp).__name__}")
    policy = as_index_array(policy, "policy", size=mdp.n_actions)
    if policy.shape != (mdp.n_states,):
        raise ValueError(f"policy must give one action per state, shape ({mdp.n_states},); "
                         f"got {policy.shape}")
    return mdp.check_theta(true_theta, "true_theta"), None, policy


def _expert_and_learned_values(mdp: TabularMDP, true_theta, learned_theta, policy):
    true_theta, learned_theta, policy = _check_learned(mdp, true_theta, learned_theta, policy)
    # one solver, the expert's reward first: where the learned reward ties two actions, the
    # greedy policy it gives depends on what the solver solved before (and the results do)
    solver = OptimalQSolver(mdp)
    pi_e = solver.solve(true_theta).policy
    pi_l = solver.solve(learned_theta).policy if policy is None else policy
    reward = mdp.reward(true_theta)
    return policy_values(mdp, reward, pi_e), policy_values(mdp, reward, pi_l)


def inverse_learning_error(mdp: TabularMDP, true_theta, learned_theta=None, *,
                           policy=None) -> float:
    """The paper's ILE: ``sum_s |V^{pi_E}(s) - V^{pi_L}(s)|``.

    ``pi_E`` is greedy optimal for the true reward; ``pi_L`` greedy optimal for the learned
    reward ``learned_theta`` or, for a learner without a reward (behaviour cloning), its
    deterministic ``policy[s]`` (exactly one of the two). Both are evaluated under the true
    reward. Zero when ``pi_L`` is optimal.

    Parameters
    ----------
    mdp : TabularMDP
    true_theta : ndarray of shape (K,)
        The expert's reward weights.
    learned_theta : ndarray of shape (K,), optional
        The learned weights, whose greedy policy is scored.
    policy : ndarray of int, shape (S,), optional
        A learned deterministic policy instead (keyword only).

    Returns
    -------
    float
        The summed absolute value difference, >= 0.
    """
    v_e, v_l = _expert_and_learned_values(mdp, true_theta, learned_theta, policy)
    return float(np.abs(v_e - v_l).sum())


def normalized_inverse_learning_error(mdp: TabularMDP, true_theta, learned_theta=None, *,
                                      policy=None) -> float:
    """ILE in percent of the expert's value: ``100 ||V_E - V_L||_1 / ||V_E||_1`` (``pi_L`` as
    in :func:`inverse_learning_error`).

    Parameters
    ----------
    mdp : TabularMDP
    true_theta : ndarray of shape (K,)
    learned_theta : ndarray of shape (K,), optional
    policy : ndarray of int, shape (S,), optional
        As in :func:`inverse_learning_error`: exactly one of the two.

    Returns
    -------
    float
        The ILE in percent (0 when the learned policy is optimal; not bounded by 100).
    """
    v_e, v_l = _expert_and_learned_values(mdp, true_theta, learned_theta, policy)
    return float(100.0 * np.abs(v_e - v_l).sum() / max(np.abs(v_e).sum(), 1e-300))


def policy_mismatch(mdp: TabularMDP, true_theta, learned_theta=None, states=None, *,
                    policy=None) -> float:
    """Fraction of states (or of ``states``) where the learned greedy action is not optimal.

    The learned action is the greedy one of ``learned_theta``, or ``policy[s]`` (exactly one of
    the two, as in :func:`inverse_learning_error`). An action counts as optimal if its true
    ``Q*`` is within 1e-9 of the best (ties allowed).

    Parameters
    ----------
    mdp : TabularMDP
    true_theta : ndarray of shape (K,)
    learned_theta : ndarray of shape (K,), optional
    states : array of int, optional
        The states to count over; all by default.
    policy : ndarray of int, shape (S,), optional

    Returns
    -------
    float
        In [0, 1]; 0 when the learned policy is optimal everywhere counted.
    """
    true_theta, learned_theta, policy = _check_learned(mdp, true_theta, learned_theta, policy)
    idx = (np.arange(mdp.n_states) if states is None
           else as_index_array(states, "states", size=mdp.n_states))
    solver = OptimalQSolver(mdp)
    Q = solver.q_values(true_theta)  # first, as in _expert_and_learned_values
    pi_l = solver.solve(learned_theta).policy if policy is None else policy
    tol = 1e-9 * (1.0 + np.abs(Q).max())
    wrong = Q[idx, pi_l[idx]] < Q[idx].max(axis=1) - tol
    return float(wrong.mean())


def reward_distance(true_theta, learned_theta) -> float:
    """Euclidean distance between unit-normalized weight vectors (the scale of a reward is not
    identifiable from behaviour).

    Parameters
    ----------
    true_theta, learned_theta : ndarray of shape (K,)
        Neither all zeros.

    Returns
    -------
    float
        In [0, 2]: 0 for weights of the same direction, 2 for opposite ones.
    """
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
