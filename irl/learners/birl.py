"""Bayesian IRL by MAP estimation: MMAP-BIRL (marginalizing hidden and noisy steps) and MAP-BIRL.

Layouts: ``G[s, a]`` expected visits of each pair, ``dQ[s, a, k]``, ``pi[s, a]``.

The expert is Boltzmann-rational: ``pi(a | s; theta) = softmax_a(beta Q*(s, a; theta))``. Both
learners maximize ``log p(theta) + sum_demos log P(demo | theta)`` and share the gradient

    d/dtheta log P = sum_{s, a} G(s, a) beta (dQ(s, a) - sum_a' pi(a' | s) dQ(s, a'))

(the paper's Eq. for the likelihood gradient, rearranged): for MMAP-BIRL, ``G`` is the sum over
time of the posterior marginals ``P(s_t, a_t | o, theta)`` from forward-backward; for MAP-BIRL,
``G`` counts the observed pairs taken at face value. ``dQ = dQ*/dtheta`` comes from one linear
solve per greedy policy and is cached (:class:`irl.solvers.OptimalQSolver`).

The policy enters the likelihood as ``log pi = log_softmax(beta Q*)``, never exponentiated
first, so the likelihood stays finite at any finite theta (see :mod:`irl.inference`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from irl._blas import one_blas_thread
from irl._random import check_random_state
from irl._validation import check_int, check_real, describe
from irl.demonstrations import Demonstration
from irl.inference import check_backend, pack_demonstrations, posterior_stats, scratch_held
from irl.learners.base import LearnerBase
from irl.learners.optimize import maximize_gradient_ascent, maximize_lbfgs
from irl.mdp import TabularMDP
from irl.observation import ObservationModel
from irl.observation.swap import SessionSwap
from irl.priors import GaussianPrior
from irl.solvers import OptimalQSolver, OptimalSolution, log_boltzmann_policy

__all__ = ["MAPBIRL", "MMAPBIRL"]

OPTIMIZERS = ("lbfgs", "gradient-ascent")


@dataclass(frozen=True)
class _Model:
    """The validated model of one call: what the likelihood and its gradient need."""

    mdp: TabularMDP
    observation_model: ObservationModel
    beta: float
    prior: GaussianPrior
    solver: OptimalQSolver


class _BayesianIRL(LearnerBase):
    """Shared machinery: objective, gradient, optimizers. Subclasses define ``_pair_stats``.

    Nothing is computed at construction: every call (``fit``, ``log_likelihood``, ...) checks
    the current hyperparameters and builds its solver from the current ``mdp``.
    """

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

    # -- the model ------------------------------------------------------------------------

    def _check_model(self) -> _Model:
        """Validate ``mdp``, ``observation_model``, ``beta`` and ``prior``; a fresh solver."""
        self._check_problem()
        beta = check_real(self.beta, "beta", low=0.0, low_open=True)
        prior = GaussianPrior() if self.prior is None else self.prior
        if not isinstance(prior, GaussianPrior):
            raise TypeError(f"prior must be an irl.GaussianPrior or None; got "
                            f"{describe(self.prior)}")
        prior._broadcast(self.mdp.n_features)
        return _Model(self.mdp, self.observation_model, beta, prior, OptimalQSolver(self.mdp))

    def _check_call(self, theta, demos) -> tuple[_Model, np.ndarray, object]:
        model = self._check_model()
        demos = self._check_problem(demos)
        return model, self.mdp.check_theta(theta), self._prepare(model, demos)

    def _prepare(self, model: _Model, demos: list[Demonstration]):
        """What ``_pair_stats`` needs of validated demonstrations, computed once per call
        (once per fit, not once per optimizer step)."""
        raise NotImplementedError

    @staticmethod
    def _log_policy(model: _Model, theta: np.ndarray) -> tuple[OptimalSolution, np.ndarray]:
        sol = model.solver.solve(theta)
        return sol, log_boltzmann_policy(sol.q_values(theta), model.beta)

    def _pair_stats(self, model: _Model, log_pi, data) -> tuple[float, np.ndarray]:
        """``(log-likelihood, G[s, a])`` under ``log pi`` of the demonstrations as
        prepared by ``_prepare``."""
        raise NotImplementedError

    def _likelihood_and_gradient(self, model: _Model, theta, data) -> tuple[float, np.ndarray]:
        # one BLAS thread on large MDPs (irl._blas): the solve, the pass and the product below
        with one_blas_thread(model.mdp.n_states * model.mdp.n_actions):
            sol, log_pi = self._log_policy(model, theta)
            ll, G = self._pair_stats(model, log_pi, data)
            # sum_{s,a} (G(s, a) - pi(a | s) sum_a' G(s, a')) dQ(s, a): one product
            weights = G - np.exp(log_pi) * G.sum(axis=1, keepdims=True)
            S, A, K = sol.dQ.shape
            grad = model.beta * (weights.reshape(S * A) @ sol.dQ.reshape(S * A, K))
        return ll, grad

    def log_likelihood(self, theta: np.ndarray, demos: Sequence[Demonstration]) -> float:
        """Natural log of ``prod_demos P(o_1..T | theta)``; finite for any finite theta
        unless a demonstration is impossible under the model (a ``ValueError``)."""
        model, theta, data = self._check_call(theta, demos)
        return float(self._pair_stats(model, self._log_policy(model, theta)[1], data)[0])

    def log_likelihood_gradient(
        self, theta: np.ndarray, demos: Sequence[Demonstration]
    ) -> np.ndarray:
        """Gradient of :meth:`log_likelihood` in theta, shape (K,)."""
        model, theta, data = self._check_call(theta, demos)
        return self._likelihood_and_gradient(model, theta, data)[1]

    def log_posterior(self, theta: np.ndarray, demos: Sequence[Demonstration]) -> float:
        """``log p(theta) + log-likelihood`` (up to the evidence)."""
        model, theta, data = self._check_call(theta, demos)
        ll = self._pair_stats(model, self._log_policy(model, theta)[1], data)[0]
        return float(ll) + model.prior.log_prob(theta)

    def log_posterior_gradient(
        self, theta: np.ndarray, demos: Sequence[Demonstration]
    ) -> np.ndarray:
        """Gradient of :meth:`log_posterior`, shape (K,)."""
        model, theta, data = self._check_call(theta, demos)
        grad = self._likelihood_and_gradient(model, theta, data)[1]
        return grad + model.prior.grad_log_prob(theta)

    def log_posterior_function(self, demos: Sequence[Demonstration]):
        """``theta -> (log posterior, gradient)`` for these demonstrations, checked once.

        The model and the demonstrations are validated and prepared here, not at each call,
        so the function suits an optimizer's or a sampler's inner loop (``theta`` is taken as
        a finite float array of shape (K,) without checks). Values are those of
        :meth:`log_posterior` and :meth:`log_posterior_gradient`.
        """
        return self._objective(self._check_model(), demos)

    def log_posterior_value_function(self, demos: Sequence[Demonstration]):
        """``theta -> log posterior`` for these demonstrations, checked once: the value of
        :meth:`log_posterior_function` without its gradient (no product with ``dQ``), for
        a caller that needs only values (importance weights).

        Prepared as :meth:`log_posterior_function` is (``theta`` taken as a finite float
        array of shape (K,) without checks); values equal its value and :meth:`log_posterior`.
        """
        return self._objectives(self._check_model(), demos)[1]

    def _objective(self, model: _Model, demos):
        return self._objectives(model, demos)[0]

    def _objectives(self, model: _Model, demos):
        """``(theta -> (log posterior, gradient), theta -> log posterior)`` on one
        preparation of the demonstrations and one solver (whose cached policies both use)."""
        data = self._prepare(model, self._check_problem(demos))
        log_prior = model.prior._value_and_grad(self.mdp.n_features)

        def value_and_gradient(theta: np.ndarray) -> tuple[float, np.ndarray]:
            ll, grad = self._likelihood_and_gradient(model, theta, data)
            value, prior_grad = log_prior(theta)
            return ll + value, grad + prior_grad

        def value(theta: np.ndarray) -> float:
            with one_blas_thread(model.mdp.n_states * model.mdp.n_actions):
                ll = self._pair_stats(model, self._log_policy(model, theta)[1], data)[0]
            return ll + log_prior(theta)[0]

        return value_and_gradient, value

    # -- fitting --------------------------------------------------------------------------

    def _check_search(self) -> dict:
        """Validate the optimizer's hyperparameters."""
        if not isinstance(self.optimizer, str):
            raise TypeError(f"optimizer must be one of {OPTIMIZERS}; got "
                            f"{describe(self.optimizer)}")
        if self.optimizer not in OPTIMIZERS:
            raise ValueError(f"optimizer must be one of {OPTIMIZERS}; got {self.optimizer!r}")
        return {
            "n_restarts": check_int(self.n_restarts, "n_restarts", low=1),
            "max_iter": check_int(self.max_iter, "max_iter", low=1),
            "tol": check_real(self.tol, "tol", low=0.0),
            "step_size": check_real(self.step_size, "step_size", low=0.0, low_open=True),
            "decay": check_real(self.decay, "decay", low=0.0, high=1.0, low_open=True),
            "epsilon": check_real(self.epsilon, "epsilon", low=0.0),
            "init": self._check_init(),
            "rng": check_random_state(self.seed),
        }

    def fit(self, demos: Sequence[Demonstration]):
        """Find the MAP reward weights. Sets ``theta_``, ``policy_``, ``log_posterior_``,
        ``n_iter_``, ``history_``, ``converged_`` and ``prior_``.

        Every hyperparameter is checked here (``ValueError``/``TypeError`` naming it), and the
        solver is built from the current ``mdp`` and ``beta``.

        Returns
        -------
        self
        """
        model = self._check_model()
        search = self._check_search()
        objective = self._objective(model, demos)  # no checks in the optimizer's loop
        prior, K = model.prior, self.mdp.n_features
        first = (np.broadcast_to(prior.mean, (K,)).astype(float)
                 if search["init"] is None else search["init"])
        starts = [first] + [prior.sample(K, search["rng"]) for _ in range(search["n_restarts"] - 1)]

        with scratch_held():  # one set of forward-backward buffers for the whole search
            if self.optimizer == "lbfgs":
                res = maximize_lbfgs(objective, starts, max_iter=search["max_iter"],
                                     tol=search["tol"])
            else:
                gamma = self.mdp.discount
                eps = search["epsilon"]
                threshold = eps * (1 - gamma) / gamma if gamma > 0 else eps
                res = maximize_gradient_ascent(
                    objective, starts, step_size=search["step_size"], decay=search["decay"],
                    threshold=threshold, max_iter=search["max_iter"],
                )
        self._solver = model.solver
        self.theta_ = res.theta
        self.log_posterior_ = res.value
        self.n_iter_ = res.n_iter
        self.history_ = res.history
        self.converged_ = res.converged
        self.prior_ = prior
        self.policy_ = model.solver.solve(self.theta_).policy
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
    backend : {"numpy", "numba"}
        Kernels of forward-backward (:data:`irl.inference.BACKENDS`): numpy and scipy, the
        default and the reference, or one compiled loop per batch (``pip install
        'onionsort[fast]'``); equal to rounding.
    session_swap : irl.observation.swap.SessionSwap, optional
        An observer failure that lasts a whole demonstration: with probability
        ``session_swap.rate`` all of a demonstration's observations were read through its
        permutation (for onion sorting, the onion's class read backwards for a whole session).
        Each demonstration's likelihood is then the mixture of it read as recorded and read
        swapped (:meth:`swap_probabilities` gives each one's posterior probability of having
        been swapped). None (the default): every step's misreading is independent, as the
        observation model says.

    Every parameter is stored as given and checked by ``fit`` (and by the ``log_*`` methods,
    which need ``mdp``, ``observation_model``, ``beta``, ``prior`` and ``backend``); change
    them with ``set_params`` or by assignment.

    Attributes
    ----------
    theta_ : ndarray of shape (K,)
    policy_ : ndarray of shape (S,)
        Greedy optimal policy for ``theta_``.
    log_posterior_ : float
    n_iter_ : int
    history_ : list of dict
    converged_ : bool
        False when the optimizer hit ``max_iter`` or was stopped by trial points where the
        objective was not finite (a :class:`~irl.ConvergenceWarning` says which).
    prior_ : GaussianPrior
        The prior used: ``prior``, or the standard normal when it is None.
    """

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
        backend: str = "numpy",
        session_swap: SessionSwap | None = None,
    ) -> None:
        super().__init__(mdp, observation_model, beta=beta, prior=prior, optimizer=optimizer,
                         n_restarts=n_restarts, max_iter=max_iter, tol=tol,
                         step_size=step_size, decay=decay, epsilon=epsilon, init=init,
                         seed=seed)
        self.backend = backend
        self.session_swap = session_swap

    def _check_swap(self, model) -> SessionSwap | None:
        swap = self.session_swap
        if swap is None:
            return None
        if not isinstance(swap, SessionSwap):
            raise TypeError(f"session_swap must be an irl.observation.swap.SessionSwap or "
                            f"None; got {describe(swap)}")
        if swap.n_observations != model.observation_model.n_observations:
            raise ValueError(f"session_swap permutes {swap.n_observations} observations; the "
                             f"observation model has {model.observation_model.n_observations}")
        return swap

    def _prepare(self, model, demos):
        swap = self._check_swap(model)
        packed = pack_demonstrations(demos, model.observation_model)
        swapped = (None if swap is None else
                   pack_demonstrations([swap.apply(d) for d in demos], model.observation_model))
        return packed, swapped, swap, check_backend(self.backend)

    def _mixture(self, model, log_pi, data):
        """Per demonstration: the log-likelihoods read as recorded and read swapped (each
        with its prior weight), their mixture, and the occupancies of both readings."""
        packed, swapped, swap, backend = data
        plain = posterior_stats(model.mdp, log_pi, packed, backend=backend)
        alt = posterior_stats(model.mdp, log_pi, swapped, backend=backend)
        a = np.log1p(-swap.rate) + plain.log_likelihood
        b = np.log(swap.rate) + alt.log_likelihood
        return a, b, np.logaddexp(a, b), plain.occupancy, alt.occupancy

    def _pair_stats(self, model, log_pi, data):
        packed, swapped, _, backend = data
        if swapped is None:
            stats = posterior_stats(model.mdp, log_pi, packed, backend=backend)
            return float(stats.log_likelihood.sum()), stats.occupancy.sum(axis=0)
        # the mixture's gradient: each reading's, weighted by its posterior probability
        a, _, total, occ_plain, occ_swapped = self._mixture(model, log_pi, data)
        kept = np.exp(a - total)[:, None, None]
        G = (kept * occ_plain + (1.0 - kept) * occ_swapped).sum(axis=0)
        return float(total.sum()), G

    def swap_probabilities(self, theta: np.ndarray,
                           demos: Sequence[Demonstration]) -> np.ndarray:
        """``(N,)``: each demonstration's posterior probability, at reward weights ``theta``,
        of having been read through ``session_swap`` (zeros without one)."""
        model, theta, data = self._check_call(theta, demos)
        if data[1] is None:
            return np.zeros(data[0].n_demos)
        _, b, total, _, _ = self._mixture(model, self._log_policy(model, theta)[1], data)
        return np.exp(b - total)


class MAPBIRL(_BayesianIRL):
    """MAP Bayesian IRL (Choi & Kim 2011) that takes observations at face value.

    Each observed step is read as the pair ``observation_model.nominal[o]`` and scored by
    ``log pi(a | s)``; occluded steps are dropped. With the identity observation model and no
    occlusion this is the same estimator as :class:`MMAPBIRL` (their log-likelihoods differ by
    the theta-independent ``log p0 + sum log T``).

    Parameters
    ----------
    mdp, observation_model, beta, prior, optimizer, n_restarts
        As :class:`MMAPBIRL`'s; an observation must report a pair (``nominal[o]`` with an
        action), so a state-only model is refused.
    max_iter, tol, step_size, decay, epsilon, init, seed
        As :class:`MMAPBIRL`'s. MAP-BIRL runs no forward-backward, so it has no ``backend``,
        and reads no session swap.

    Attributes
    ----------
    theta_, policy_, log_posterior_, n_iter_, history_, converged_, prior_
        As :class:`MMAPBIRL`'s, for the face-value posterior.
    """

    def _prepare(self, model, demos):
        return face_value_counts(demos, model.observation_model)

    def _pair_stats(self, model, log_pi, G):
        seen = G > 0
        return float((G[seen] * log_pi[seen]).sum()), G


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
                f"demos[{i}], step {t}: observation {obs[t]} reports no action, so it "
                "cannot be taken at face value (use MMAPBIRL or HiddenDataEM)"
            )
        np.add.at(G, (pairs[:, 0], pairs[:, 1]), 1.0)
    return G
