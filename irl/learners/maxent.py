"""Maximum-causal-entropy IRL: MaxEntIRL on observed steps, and HiddenDataEM.

Layouts: ``log_pi[h - 1, s, a]`` is the soft-optimal policy with ``h`` steps to go
(h = 1..H), ``D0[s]`` start-state weights, ``fbar[k]`` feature counts.

Finite-horizon MCE IRL (Ziebart et al. 2010) in its dual form: with the soft Bellman backup
``Q_h = R + T V_{h-1}``, ``V_h = logsumexp_a Q_h``, ``V_0 = 0``, the convex objective

    J(theta) = sum_groups D0 . V_H(theta) - theta . fbar + (l2 / 2) |theta|^2

has gradient ``E_pi[sum_t phi] - fbar + l2 theta`` (expected minus demonstrated feature counts),
so its minimizer matches feature counts. ``l2`` keeps the weights finite when a feature never
occurs in the data; it is small by default.

HiddenDataEM (Bogert et al. 2016, extended with the observation model as in the paper) is latent
MCE IRL: the E-step computes the exact posterior over each demonstration's hidden ``(s, a)``
under the current soft policy and observation model (forward-backward), the M-step fits MCE IRL
to the expected feature counts, and it stops when the weights change by less than ``tol`` or
after ``max_iter`` (100) iterations.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np
from scipy.special import logsumexp

from irl._validation import check_int, check_real
from irl.demonstrations import Demonstration
from irl.exceptions import ConvergenceWarning
from irl.inference import (
    PackedDemonstrations,
    pack_demonstrations,
    posterior_stats,
    scratch_held,
)
from irl.learners.base import LearnerBase
from irl.learners.optimize import maximize_lbfgs
from irl.mdp import TabularMDP
from irl.observation import ObservationModel
from irl.solvers import OptimalQSolver

__all__ = [
    "HiddenDataEM",
    "MaxEntIRL",
    "expected_feature_counts",
    "mce_dual",
    "soft_backward",
]

# {horizon H: (D0[s] summed over trajectories of that horizon, fbar[k] summed likewise)}
Groups = dict[int, tuple[np.ndarray, np.ndarray]]


def soft_backward(mdp: TabularMDP, reward: np.ndarray, horizon: int):
    """Finite-horizon soft value iteration (undiscounted).

    Parameters
    ----------
    mdp : TabularMDP
    reward : ndarray of shape (S, A)
    horizon : int
        Steps to go at the start, >= 1.

    Returns
    -------
    log_pi : ndarray of shape (horizon, S, A)
        ``log_pi[h - 1]`` is the policy with h steps to go.
    V : ndarray of shape (horizon + 1, S)
        ``V[h]``, the soft value with h steps to go.
    """
    V = np.zeros((horizon + 1, mdp.n_states))
    log_pi = np.empty((horizon, mdp.n_states, mdp.n_actions))
    for h in range(1, horizon + 1):
        Q = reward + mdp.expect_next(V[h - 1])
        V[h] = logsumexp(Q, axis=1)
        log_pi[h - 1] = Q - V[h][:, None]
    return log_pi, V


def time_indexed(log_pi: np.ndarray, length: int) -> np.ndarray:
    """``pi[t, s, a]`` for t = 0..length-1 of a trajectory of that length (h = length - t)."""
    return np.exp(log_pi[:length][::-1])


def expected_feature_counts(mdp: TabularMDP, log_pi: np.ndarray, D0: np.ndarray, horizon: int):
    """``E[sum_{t < horizon} phi(s_t, a_t)]`` from start weights ``D0`` (need not sum to 1).

    Parameters
    ----------
    mdp : TabularMDP
    log_pi : ndarray of shape (>= horizon, S, A)
        The time-indexed soft policy of :func:`soft_backward`.
    D0 : ndarray of shape (S,)
        Start-state weights.
    horizon : int

    Returns
    -------
    ndarray of shape (K,)
        The expected feature counts, scaled as ``D0``.
    """
    d = D0
    counts = np.zeros(mdp.n_features)
    for t in range(horizon):
        sa = d[:, None] * np.exp(log_pi[horizon - 1 - t])
        counts += np.einsum("sa,sak->k", sa, mdp.features)
        if t + 1 < horizon:
            d = mdp.push_forward(sa)
    return counts


def mce_dual(mdp: TabularMDP, theta: np.ndarray, groups: Groups, l2: float):
    """Value and gradient of the MCE dual ``J(theta)`` (see the module docstring).

    Parameters
    ----------
    mdp : TabularMDP
    theta : ndarray of shape (K,)
    groups : dict of int to (ndarray, ndarray)
        Per horizon ``H``, the start weights ``D0[s]`` and feature counts ``fbar[k]`` of the
        demonstrated runs of that length, summed.
    l2 : float
        The L2 penalty's weight.

    Returns
    -------
    value : float
        ``J(theta)``, which the fit minimizes.
    grad : ndarray of shape (K,)
        Its gradient: expected minus demonstrated feature counts, plus ``l2 theta``.
    """
    horizon = max(groups)
    log_pi, V = soft_backward(mdp, mdp.features @ theta, horizon)
    value = 0.5 * l2 * theta @ theta
    grad = l2 * theta
    for H, (D0, fbar) in groups.items():
        value += D0 @ V[H] - theta @ fbar
        grad = grad + expected_feature_counts(mdp, log_pi, D0, H) - fbar
    return float(value), grad


def _fit_dual(mdp, groups: Groups, theta0: np.ndarray, l2: float, max_iter: int, tol: float):
    """Minimize the MCE dual by L-BFGS-B from ``theta0``; ``(theta, n_iter, converged,
    history)``. A non-finite dual is a failed line-search step
    (:func:`irl.learners.optimize.maximize_lbfgs`)."""

    def objective(th):
        value, grad = mce_dual(mdp, th, groups, l2)
        return -value, -grad

    res = maximize_lbfgs(objective, [theta0], max_iter=max_iter, tol=tol, warn=False)
    return res.theta, res.n_iter, res.converged, res.history


class _MCEBase(LearnerBase):
    """Shared checks and fitted state of the maximum-causal-entropy learners."""

    def _check_mce(self) -> dict:
        return {
            "l2": check_real(self.l2, "l2", low=0.0),
            "max_iter": check_int(self.max_iter, "max_iter", low=1),
            "tol": check_real(self.tol, "tol", low=0.0),
            "init": self._check_init(),
        }

    def _theta0(self, init) -> np.ndarray:
        return np.zeros(self.mdp.n_features) if init is None else init

    def _finish(self, theta: np.ndarray) -> None:
        self.theta_ = theta
        self.policy_ = OptimalQSolver(self.mdp).solve(theta).policy

    def soft_policy(self, length: int) -> np.ndarray:
        """The fitted time-indexed soft policy ``pi[t, s, a]`` for a trajectory of ``length``."""
        self._check_fitted()
        length = check_int(length, "length", low=1)
        log_pi, _ = soft_backward(self.mdp, self.mdp.reward(self.theta_), length)
        return time_indexed(log_pi, length)


class MaxEntIRL(_MCEBase):
    """Maximum-causal-entropy IRL on the observed steps only.

    Observations are read at face value (``observation_model.nominal``) and each maximal run of
    consecutive observed steps is a trajectory of its own; occluded steps are dropped and noise
    is ignored.

    Parameters
    ----------
    mdp : TabularMDP
    observation_model : ObservationModel
    l2 : float, default 0.01
        Weak L2 penalty that keeps weights finite.
    max_iter, tol : int, float
        Bounds of the L-BFGS fit of the dual.
    init : ndarray of shape (K,), optional
        Initial weights (zeros by default).

    Attributes
    ----------
    theta_ : ndarray of shape (K,)
    policy_ : ndarray of shape (S,)
        Greedy optimal (discounted) policy for ``theta_``, as for every learner.
    n_iter_ : int
    history_ : list of dict
        Per evaluation of the dual: ``iteration`` and ``value`` (minus the dual).
    converged_ : bool
        Whether L-BFGS met ``tol`` before ``max_iter``.
    """

    def __init__(self, mdp, observation_model, *, l2=0.01, max_iter=500, tol=1e-8, init=None):
        self.mdp = mdp
        self.observation_model = observation_model
        self.l2 = l2
        self.max_iter = max_iter
        self.tol = tol
        self.init = init

    def fit(self, demos: Sequence[Demonstration]):
        """Fit the reward weights to the observed runs; returns ``self``."""
        self._check_problem()
        params = self._check_mce()
        demos = self._check_problem(demos)
        groups = observed_segments(demos, self.mdp, self.observation_model)
        theta, n_iter, converged, history = _fit_dual(
            self.mdp, groups, self._theta0(params["init"]), params["l2"], params["max_iter"],
            params["tol"],
        )
        if not converged:
            warnings.warn(
                f"MaxEntIRL stopped at max_iter={params['max_iter']} (or at a non-finite dual) "
                f"before reaching tol={params['tol']}", ConvergenceWarning, stacklevel=2,
            )
        self.n_iter_ = n_iter
        self.history_ = history
        self.converged_ = converged
        self._finish(theta)
        return self


def observed_segments(demos, mdp: TabularMDP, observation_model) -> Groups:
    """MCE groups from the maximal runs of observed steps, read at face value."""
    nominal = observation_model.nominal
    groups: Groups = {}
    for i, d in enumerate(demos):
        obs = d.as_array()
        t = 0
        while t < len(obs):
            if obs[t] < 0:
                t += 1
                continue
            end = t
            while end < len(obs) and obs[end] >= 0:
                end += 1
            pairs = nominal[obs[t:end]]
            if np.any(pairs[:, 1] < 0):
                step = t + int(np.flatnonzero(pairs[:, 1] < 0)[0])
                raise ValueError(
                    f"demos[{i}], step {step}: observation {obs[step]} reports no "
                    "action, so it cannot be taken at face value (use HiddenDataEM or MMAPBIRL)"
                )
            H = end - t
            D0, fbar = groups.setdefault(
                H, (np.zeros(mdp.n_states), np.zeros(mdp.n_features))
            )
            D0[pairs[0, 0]] += 1.0
            fbar += mdp.features[pairs[:, 0], pairs[:, 1]].sum(axis=0)
            t = end
    if not groups:
        raise ValueError(
            "demos must hold at least one observed step; every step of every demonstration is "
            "occluded, so MaxEntIRL has nothing to learn from (MMAPBIRL and HiddenDataEM accept "
            "this)"
        )
    return groups


class HiddenDataEM(_MCEBase):
    """Latent maximum-causal-entropy IRL by expectation-maximization (the paper's baseline).

    Parameters
    ----------
    mdp : TabularMDP
    observation_model : ObservationModel
        Used in the E-step exactly as MMAP-BIRL uses it.
    l2 : float, default 0.01
        Weak L2 penalty in the M-step that keeps weights finite.
    max_iter : int, default 100
        EM iterations (Bogert et al.'s limit).
    tol : float, default 1e-3
        Stop when ``max_k |theta_new - theta|_k < tol``.
    m_step_max_iter, m_step_tol : int, float
        L-BFGS limits of each M-step.
    init : ndarray of shape (K,), optional
        Initial weights (zeros by default).

    Attributes
    ----------
    theta_ : ndarray of shape (K,)
    policy_ : ndarray of shape (S,)
    n_iter_ : int
        EM iterations run.
    history_ : list of dict
        Per iteration: ``log_likelihood`` of the observations under the E-step policy and the
        weight change ``delta``.
    converged_ : bool
        Whether the weights changed by less than ``tol`` before ``max_iter``.
    """

    def __init__(
        self,
        mdp: TabularMDP,
        observation_model: ObservationModel,
        *,
        l2: float = 0.01,
        max_iter: int = 100,
        tol: float = 1e-3,
        m_step_max_iter: int = 200,
        m_step_tol: float = 1e-8,
        init: np.ndarray | None = None,
    ) -> None:
        self.mdp = mdp
        self.observation_model = observation_model
        self.l2 = l2
        self.max_iter = max_iter
        self.tol = tol
        self.m_step_max_iter = m_step_max_iter
        self.m_step_tol = m_step_tol
        self.init = init

    def e_step(self, theta: np.ndarray, demos: Sequence[Demonstration]):
        """Posterior statistics of the demonstrations under the soft policy of ``theta``."""
        demos = self._check_problem(demos)
        theta = self.mdp.check_theta(theta)
        return self._e_step(theta, self._pack(demos))

    def _pack(self, demos) -> PackedDemonstrations:
        return pack_demonstrations(demos, self.observation_model, equal_lengths=True)

    def _e_step(self, theta, packed: PackedDemonstrations):
        horizon = max(obs.shape[1] for obs in packed.obs)
        log_pi, _ = soft_backward(self.mdp, self.mdp.features @ theta, horizon)
        return posterior_stats(
            self.mdp, None, packed, log_policies_by_length=lambda T: log_pi[:T][::-1],
        )

    def fit(self, demos: Sequence[Demonstration]):
        """Fit by EM; returns ``self``. Every hyperparameter is checked here."""
        self._check_problem()
        params = self._check_mce()
        m_max_iter = check_int(self.m_step_max_iter, "m_step_max_iter", low=1)
        m_tol = check_real(self.m_step_tol, "m_step_tol", low=0.0)
        demos = self._check_problem(demos)
        packed = self._pack(demos)
        theta = self._theta0(params["init"])
        history: list[dict] = []
        converged = False
        delta = np.inf
        with scratch_held():  # one set of forward-backward buffers for every E-step
            for it in range(params["max_iter"]):
                stats = self._e_step(theta, packed)
                groups: Groups = {}
                for i, d in enumerate(demos):
                    D0, fbar = groups.setdefault(
                        len(d), (np.zeros(self.mdp.n_states), np.zeros(self.mdp.n_features))
                    )
                    D0 += stats.initial[i]
                    fbar += np.einsum("sa,sak->k", stats.occupancy[i], self.mdp.features)
                new, _, _, _ = _fit_dual(self.mdp, groups, theta, params["l2"], m_max_iter, m_tol)
                delta = float(np.max(np.abs(new - theta)))
                history.append({
                    "iteration": it,
                    "log_likelihood": float(stats.log_likelihood.sum()),
                    "delta": delta,
                })
                theta = new
                if delta < params["tol"]:
                    converged = True
                    break
        if not converged:
            warnings.warn(
                f"HiddenDataEM stopped at max_iter={params['max_iter']} with the weights still "
                f"changing by {delta:.3g} > tol={params['tol']}",
                ConvergenceWarning, stacklevel=2,
            )
        self.n_iter_ = len(history)
        self.history_ = history
        self.converged_ = converged
        self._finish(theta)
        return self
