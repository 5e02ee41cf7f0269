"""Bayesian IRL by MAP estimation: MMAP-BIRL (marginalizing hidden and noisy steps) and MAP-BIRL.

Layouts: ``G[s, a]`` expected visits of each pair, ``dQ[s, a, k]``, ``pi[s, a]``.

The expert is Boltzmann-rational: ``pi(a | s; theta) = softmax_a(beta Q*(s, a; theta))``. Both
learners maximize ``log p(theta) + sum_demos log P(demo | theta)`` and share the gradient

    d/dtheta log P = sum_{s, a} G(s, a) beta (dQ(s, a) - sum_a' pi(a' | s) dQ(s, a'))

(the paper's Eq. for the likelihood gradient, rearranged): for MMAP-BIRL, ``G`` is the sum over
time of the posterior marginals ``P(s_t, a_t | o, theta)`` from forward-backward; for MAP-BIRL,
``G`` counts the observed pairs taken at face value. ``dQ = dQ*/dtheta`` comes from one linear
solve per greedy policy and is cached (:class:`irl.solvers.OptimalQSolver`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from irl._random import check_random_state
from irl.demonstrations import Demonstration, check_demonstrations
from irl.inference import posterior_stats
from irl.learners.optimize import maximize_gradient_ascent, maximize_lbfgs
from irl.mdp import TabularMDP
from irl.observation import ObservationModel, check_compatible
from irl.priors import GaussianPrior
from irl.solvers import OptimalQSolver, OptimalSolution, boltzmann_policy

__all__ = ["MAPBIRL", "MMAPBIRL"]

OPTIMIZERS = ("lbfgs", "gradient-ascent")


class _BayesianIRL:
    """Shared machinery: objective, gradient, optimizers. Subclasses define ``_pair_stats``."""

    def __init__(
        self,
        mdp: TabularMDP,
        observation_model: ObservationModel,
        *,
        beta: float = 1.0,
        prior: GaussianPrior | None = None,
        optimizer: str = "lbfgs",
        n_restarts: int = 1,
        max_iter: int = 200,
        tol: float = 1e-6,
        step_size: float = 0.01,
        decay: float = 0.95,
        epsilon: float = 0.01,
        init: np.ndarray | None = None,
        seed: int | np.random.Generator | None = None,
    ) -> None:
        self.mdp = mdp
        self.observation_model = observation_model
        self.beta = beta
        self.prior = prior
        self.optimizer = optimizer
        self.n_restarts = n_restarts
        self.max_iter = max_iter
        self.tol = tol
        self.step_size = step_size
        self.decay = decay
        self.epsilon = epsilon
        self.init = init
        self.seed = seed
        self._solver = OptimalQSolver(mdp)

    # -- the model ------------------------------------------------------------------------

    @property
    def prior_(self) -> GaussianPrior:
        return GaussianPrior() if self.prior is None else self.prior

    def _policy(self, theta: np.ndarray) -> tuple[OptimalSolution, np.ndarray]:
        sol = self._solver.solve(theta)
        return sol, boltzmann_policy(sol.q_values(theta), self.beta)

    def _pair_stats(self, pi, demos) -> tuple[float, np.ndarray]:
        """``(log-likelihood, G[s, a])`` of the demonstrations under policy ``pi``."""
        raise NotImplementedError

    def _likelihood_and_gradient(self, theta, demos) -> tuple[float, np.ndarray]:
        sol, pi = self._policy(theta)
        ll, G = self._pair_stats(pi, demos)
        expected_dQ = np.einsum("sa,sak->sk", pi, sol.dQ)
        grad = self.beta * (
            np.einsum("sa,sak->k", G, sol.dQ) - np.einsum("s,sk->k", G.sum(axis=1), expected_dQ)
        )
        return ll, grad

    def _check(self, theta, demos) -> tuple[np.ndarray, list[Demonstration]]:
        check_compatible(self.mdp, self.observation_model)
        if not np.isscalar(self.beta) or not self.beta > 0:
            raise ValueError(f"beta must be a positive number; got {self.beta!r}")
        demos = check_demonstrations(demos, self.observation_model.n_observations)
        theta = None if theta is None else self.mdp.check_theta(theta)
        return theta, demos

    def log_likelihood(self, theta: np.ndarray, demos: Sequence[Demonstration]) -> float:
        """Natural log of ``prod_demos P(o_1..T | theta)``."""
        theta, demos = self._check(theta, demos)
        return float(self._pair_stats(self._policy(theta)[1], demos)[0])

    def log_likelihood_gradient(
        self, theta: np.ndarray, demos: Sequence[Demonstration]
    ) -> np.ndarray:
        """Gradient of :meth:`log_likelihood` in theta, shape (K,)."""
        theta, demos = self._check(theta, demos)
        return self._likelihood_and_gradient(theta, demos)[1]

    def log_posterior(self, theta: np.ndarray, demos: Sequence[Demonstration]) -> float:
        """``log p(theta) + log-likelihood`` (up to the evidence)."""
        theta, demos = self._check(theta, demos)
        return self.log_likelihood(theta, demos) + self.prior_.log_prob(theta)

    def log_posterior_gradient(
        self, theta: np.ndarray, demos: Sequence[Demonstration]
    ) -> np.ndarray:
        """Gradient of :meth:`log_posterior`, shape (K,)."""
        theta, demos = self._check(theta, demos)
        return self._likelihood_and_gradient(theta, demos)[1] + self.prior_.grad_log_prob(theta)

    # -- fitting --------------------------------------------------------------------------

    def fit(self, demos: Sequence[Demonstration]):
        """Find the MAP reward weights. Sets ``theta_``, ``policy_``, ``n_iter_``, ``history_``.

        Returns
        -------
        self
        """
        _, demos = self._check(None, demos)
        if self.optimizer not in OPTIMIZERS:
            raise ValueError(f"optimizer must be one of {OPTIMIZERS}; got {self.optimizer!r}")
        if self.n_restarts < 1:
            raise ValueError(f"n_restarts must be >= 1; got {self.n_restarts}")
        rng = check_random_state(self.seed)
        prior = self.prior_
        K = self.mdp.n_features
        first = (
            np.broadcast_to(prior.mean, (K,)).astype(float)
            if self.init is None else self.mdp.check_theta(self.init)
        )
        starts = [first] + [prior.sample(K, rng) for _ in range(self.n_restarts - 1)]

        def objective(theta):
            ll, grad = self._likelihood_and_gradient(theta, demos)
            return ll + prior.log_prob(theta), grad + prior.grad_log_prob(theta)

        if self.optimizer == "lbfgs":
            res = maximize_lbfgs(objective, starts, max_iter=self.max_iter, tol=self.tol)
        else:
            gamma = self.mdp.discount
            threshold = self.epsilon * (1 - gamma) / gamma if gamma > 0 else self.epsilon
            res = maximize_gradient_ascent(
                objective, starts, step_size=self.step_size, decay=self.decay,
                threshold=threshold, max_iter=self.max_iter,
            )
        self.theta_ = res.theta
        self.log_posterior_ = res.value
        self.n_iter_ = res.n_iter
        self.history_ = res.history
        self.converged_ = res.converged
        self.policy_ = self._solver.solve(self.theta_).policy
        return self


class MMAPBIRL(_BayesianIRL):
    """Marginal MAP Bayesian IRL under occlusion with observer noise.

    Maximizes ``log p(theta) + sum_demos log sum_{s_1..T, a_1..T} P(o, s, a | theta)``: every
    hidden pair sequence is marginalized exactly by forward-backward, occluded steps included,
    and the observation model ``O[s, a, o]`` is used as given.

    Parameters
    ----------
    mdp : TabularMDP
    observation_model : ObservationModel
    beta : float, default 1.0
        Boltzmann rationality assumed for the expert. Only ``beta * theta`` is identified from
        behaviour, so beta sets the scale at which the prior is read: with the default standard
        normal prior, beta = 1 puts ``beta * theta`` on the prior's scale. The paper's 0.03
        makes that prior pin the weights near 0 (measured on onion sorting, 20 batches of 10
        demonstrations at 30% noise, 20% occlusion: normalized ILE 14.7% at 0.03, 0 at 1.0;
        Forestworld is insensitive). Pass the domain's beta (``domain.beta``) and prior when
        known; see docs/paper-errata.md.
    prior : GaussianPrior, optional
        Prior on theta; standard normal per weight by default.
    optimizer : {"lbfgs", "gradient-ascent"}
        L-BFGS-B from ``n_restarts`` starts (default), or the paper's Algorithm 1.
    n_restarts : int, default 1
        Starts: the prior mean (or ``init``) and ``n_restarts - 1`` draws from the prior. On
        the paper's domains extra starts found the same optimum in every batch we tried; raise
        it for posteriors with several modes.
    max_iter, tol : int, float
        Per-start iteration limit and L-BFGS tolerance.
    step_size, decay, epsilon : float
        Algorithm 1's step 0.01, decay 0.95 and stopping epsilon (threshold
        ``epsilon (1 - gamma) / gamma``).
    init : ndarray of shape (K,), optional
        First start instead of the prior mean.
    seed : int or Generator, optional
        Seeds the restarts.

    Attributes
    ----------
    theta_ : ndarray of shape (K,)
    policy_ : ndarray of shape (S,)
        Greedy optimal policy for ``theta_``.
    log_posterior_ : float
    n_iter_ : int
    history_ : list of dict
    converged_ : bool
    """

    def _pair_stats(self, pi, demos):
        stats = posterior_stats(self.mdp, pi, demos, self.observation_model)
        return float(stats.log_likelihood.sum()), stats.occupancy.sum(axis=0)


class MAPBIRL(_BayesianIRL):
    """MAP Bayesian IRL (Choi & Kim 2011) that takes observations at face value.

    Each observed step is read as the pair ``observation_model.nominal[o]`` and scored by
    ``log pi(a | s)``; occluded steps are dropped. With the identity observation model and no
    occlusion this is the same estimator as :class:`MMAPBIRL` (their log-likelihoods differ by
    the theta-independent ``log p0 + sum log T``). Parameters are those of :class:`MMAPBIRL`.
    """

    def _pair_stats(self, pi, demos):
        G = face_value_counts(demos, self.observation_model)
        return float((G[G > 0] * np.log(pi[G > 0])).sum()), G


def face_value_counts(demos: Sequence[Demonstration], observation_model) -> np.ndarray:
    """``G[s, a]``: how often each pair was observed, reading observations at face value."""
    nominal = observation_model.nominal
    G = np.zeros((observation_model.n_states, observation_model.n_actions))
    for i, d in enumerate(demos):
        obs = d.as_array()
        seen = obs[obs >= 0]
        pairs = nominal[seen]
        if np.any(pairs[:, 1] < 0):
            t = int(np.flatnonzero(obs >= 0)[np.flatnonzero(pairs[:, 1] < 0)[0]])
            raise ValueError(
                f"demonstration {i}, step {t}: observation {obs[t]} reports no action, so it "
                "cannot be taken at face value (use MMAPBIRL or HiddenDataEM)"
            )
        np.add.at(G, (pairs[:, 0], pairs[:, 1]), 1.0)
    return G
