"""What the posterior says about the MAP policy: its value at risk under every sample's reward
(:func:`map_policy_risk`), and where another demonstration is worth most
(:func:`expected_regret`).

Layouts: ``theta[n, k]`` samples, ``Q[n, s, a]`` each sample's optimal Q-function.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from irl._validation import describe
from irl.mdp import TabularMDP
from irl.posterior.result import Posterior
from irl.solvers import solve_policy_derivatives


@dataclass(frozen=True)
class PolicyRisk:
    """How the MAP policy would fare if each sample were the true reward.

    Attributes
    ----------
    ile : ndarray of shape (n,)
        ``sum_s |V*(s) - V^MAP(s)|`` under each sample's reward (the inverse learning error the
        MAP policy would have).
    normalized_ile : ndarray of shape (n,)
        ``100 * ile / ||V*||_1`` (percent).
    optimal : ndarray of shape (n,), bool
        Whether the MAP policy is optimal for the sample (values equal to rounding).
    """

    ile: np.ndarray
    normalized_ile: np.ndarray
    optimal: np.ndarray

    @property
    def expected_ile(self) -> float:
        return float(self.ile.mean())

    @property
    def expected_normalized_ile(self) -> float:
        return float(self.normalized_ile.mean())

    @property
    def p_optimal(self) -> float:
        """The posterior probability that the MAP policy is optimal."""
        return float(self.optimal.mean())

    def to_dict(self) -> dict:
        return {"expected_ile": round(self.expected_ile, 6),
                "expected_normalized_ile": round(self.expected_normalized_ile, 4),
                "p_map_optimal": round(self.p_optimal, 4),
                "ile_quantiles": {str(q): round(float(np.quantile(self.ile, q)), 6)
                                  for q in (0.5, 0.9, 0.95)}}


def _sample_q_values(posterior: Posterior, mdp: TabularMDP) -> np.ndarray:
    """``Q[n, s, a]``: each sample's optimal Q-function. ``Q^pi = dQ^pi theta`` is linear in
    theta for a fixed policy, so one linear solve per distinct greedy policy serves all the
    samples that share it."""
    unique, which = np.unique(posterior.policies, axis=0, return_inverse=True)
    Q = np.empty((posterior.n_samples, mdp.n_states, mdp.n_actions))
    for u, policy in enumerate(unique):
        rows = np.flatnonzero(which.reshape(-1) == u)
        Q[rows] = np.einsum("sak,nk->nsa", solve_policy_derivatives(mdp, policy),
                            posterior.theta[rows])
    return Q


def map_policy_risk(posterior: Posterior, mdp: TabularMDP) -> PolicyRisk:
    """Score the MAP policy under every sample's reward (its value at risk).

    Parameters
    ----------
    posterior : Posterior
        Of a learner on ``mdp``.
    mdp : TabularMDP

    Returns
    -------
    PolicyRisk
        Per sample: the MAP policy's ILE and normalized ILE against that sample's optimal
        policy, and whether it is optimal there.
    """
    _check_posterior(posterior, mdp)
    Q = _sample_q_values(posterior, mdp)
    states = np.arange(mdp.n_states)
    v_best = Q.max(axis=2)
    dV = solve_policy_derivatives(mdp, posterior.map_policy)[states, posterior.map_policy]
    v_map = posterior.theta @ dV.T  # (n, S)
    gap = np.abs(v_best - v_map).sum(axis=1)
    scale = np.abs(v_best).sum(axis=1)
    normalized = np.divide(100.0 * gap, scale, out=np.zeros_like(gap), where=scale > 0)
    return PolicyRisk(ile=gap, normalized_ile=normalized,
                      optimal=gap <= 1e-9 * np.maximum(1.0, scale))


def expected_regret(posterior: Posterior, mdp: TabularMDP) -> np.ndarray:
    """``(S,)``: ``E[max_a Q(s, a) - Q(s, pi_MAP(s))]`` over the posterior.

    What the MAP policy's action in ``s`` is expected to give up against the best action, in
    reward units: the value of perfect information about the best action in ``s``, and so an
    upper bound on what a demonstration in ``s`` can gain the robot there. Zero where every
    sample agrees with the MAP action.

    Parameters
    ----------
    posterior : Posterior
        Of a learner on ``mdp``.
    mdp : TabularMDP

    Returns
    -------
    ndarray of shape (S,)
        The expected regret of the MAP action in each state, >= 0.
    """
    _check_posterior(posterior, mdp)
    Q = _sample_q_values(posterior, mdp)
    taken = Q[:, np.arange(mdp.n_states), posterior.map_policy]
    return (Q.max(axis=2) - taken).mean(axis=0)


def _check_posterior(posterior, mdp) -> None:
    if not isinstance(posterior, Posterior):
        raise TypeError(f"posterior must be an irl.posterior.Posterior; got "
                        f"{describe(posterior)}")
    if not isinstance(mdp, TabularMDP):
        raise TypeError(f"mdp must be an irl.TabularMDP; got {describe(mdp)}")
    if posterior.policies.shape[1] != mdp.n_states or posterior.theta.shape[1] != mdp.n_features:
        raise ValueError(
            f"the posterior is over {posterior.theta.shape[1]} weights of "
            f"{posterior.policies.shape[1]} states; the mdp has {mdp.n_features} and "
            f"{mdp.n_states}")
