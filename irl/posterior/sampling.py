"""Draws from the estimator's exact posterior over reward weights (:func:`sample_posterior`).

Layouts: ``theta[n, k]`` posterior samples, ``policies[n, s]`` the greedy action of each
sample.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np

from irl._random import check_random_state
from irl._validation import check_int, check_real, describe
from irl.demonstrations import Demonstration
from irl.inference import scratch_held
from irl.learners.birl import MAPBIRL, MMAPBIRL
from irl.mdp import TabularMDP
from irl.posterior.laplace import _draw, _laplace_covariance
from irl.posterior.result import Posterior, SwapComponent
from irl.posterior.swaps import _draw_swap_readings
from irl.solvers import OptimalQSolver

logger = logging.getLogger(__name__)

#: The ways :func:`sample_posterior` draws.
METHODS = ("laplace", "mcmc")


def _check_estimator(estimator):
    if not isinstance(estimator, MMAPBIRL | MAPBIRL):
        raise TypeError("estimator must be an irl.MMAPBIRL or irl.MAPBIRL (a Bayesian learner "
                        f"with an exact log posterior); got {describe(estimator)}")
    return estimator


def _fitted_map(estimator, demos) -> tuple[np.ndarray, object]:
    """The MAP and the ``theta -> (log posterior, gradient)`` of the estimator. A fitted
    estimator's ``theta_`` is the MAP (the policy the robot runs is its greedy one, and the
    confidence is about that policy); an unfitted one is fitted on a copy."""
    if hasattr(estimator, "theta_"):
        return np.asarray(estimator.theta_, float), estimator.log_posterior_function(demos)
    fitted = type(estimator)(**estimator.get_params()).fit(demos)
    return np.asarray(fitted.theta_, float), fitted.log_posterior_function(demos)



def _greedy_policies(mdp: TabularMDP, theta: np.ndarray) -> np.ndarray:
    solver = OptimalQSolver(mdp)
    return np.stack([solver.solve(t).policy for t in theta]).astype(np.int64)



def sample_posterior(
    estimator,
    demonstrations: Sequence[Demonstration],
    n_samples: int = 1000,
    seed: int | np.random.Generator | None = 0,
    method: str = "mcmc",
    *,
    n_chains: int = 4,
    n_warmup: int = 200,
    n_draws: int | None = None,
    max_draws: int | None = None,
    step: float = 1e-4,
) -> Posterior:
    """Draw reward weights from the estimator's exact posterior given the demonstrations.

    Parameters
    ----------
    estimator : MMAPBIRL or MAPBIRL
        Its model (MDP, observation model of any kind, beta, prior, backend, session swap)
        defines the posterior. If it is fitted (on these demonstrations), its ``theta_`` is
        the MAP the samples are drawn around (with a session swap, the MAP whose policy the
        confidence is about, each reading being drawn round its own mode) and its greedy
        policy the one the confidence is about; otherwise a copy is fitted. It is not
        changed.
    demonstrations : sequence of Demonstration
    n_samples : int, default 1000
        Samples returned (the main draws of all chains, thinned evenly to this many; with a
        session swap, each reading's share of them, thinned from its own chains).
    seed : int, Generator or None, default 0
        The same seed gives the same samples.
    method : {"mcmc", "laplace"}
        See :mod:`irl.posterior`.
    n_chains : int, default 4
        Chains of ``"mcmc"``; their agreement is the R-hat.
    n_warmup : int, default 200
        Warm-up (step-size adaptation) iterations per chain, discarded.
    n_draws : int, optional
        Main draws per chain; by default ``max(400, ceil(n_samples / n_chains))``.
    max_draws : int, optional
        While the chains disagree (a weight's split R-hat above 1.01), they are extended by
        ``n_draws`` at a time up to this many draws each; by default ``3 * n_draws``. Equal
        to ``n_draws``, never.
    step : float, default 1e-4
        Relative step of the differences that give the Hessian at the MAP.

    With an :class:`~irl.MMAPBIRL` whose ``session_swap`` is set, the posterior has one mode
    per reading of the demonstrations (which of them were read swapped), and a chain started at
    one does not cross to another (the reward read backwards is far from the reward read
    right). So the readings of :func:`swap_readings` are weighed one by one: each is fitted
    without the swap on the demonstrations so read, weighted by its prior probability times
    its Laplace evidence, and drawn from as above in proportion to its weight
    (:attr:`Posterior.components`), its chains' ``n_draws`` scaled by its share of the
    samples (and extended up to ``max_draws`` while they disagree, a reading other than the
    heaviest while its gradients are fewer than the heaviest's); the lightest readings,
    together at most :data:`LAPLACE_SHARE` of the weight, are drawn from their Laplace
    approximation, and the others but the heaviest by importance resampling from it (adapted
    where it misses) where that is cheaper than chains and its effective sample size suffices
    (:data:`IMPORTANCE_PROPOSALS`, :data:`IMPORTANCE_ADAPTATIONS`). Readings outside that set
    are not weighed.

    Returns
    -------
    Posterior
    """
    estimator = _check_estimator(estimator)
    n_samples = check_int(n_samples, "n_samples", low=1)
    if not isinstance(method, str) or method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}; got {method!r}")
    n_chains = check_int(n_chains, "n_chains", low=2)
    n_warmup = check_int(n_warmup, "n_warmup", low=1)
    if n_draws is None:
        n_draws = max(400, -(-n_samples // n_chains))
    n_draws = check_int(n_draws, "n_draws", low=4)
    max_draws = check_int(3 * n_draws if max_draws is None else max_draws, "max_draws",
                          low=n_draws)
    step = check_real(step, "step", low=0.0, high=0.1, low_open=True)
    rng = check_random_state(seed)
    mdp = estimator.mdp
    demonstrations = list(demonstrations)
    draw = {"method": method, "rng": rng, "n_chains": n_chains, "n_warmup": n_warmup,
            "n_draws": n_draws, "max_draws": max_draws, "step": step}

    with scratch_held():
        map_theta, value_and_grad = _fitted_map(estimator, demonstrations)
        _, std = estimator._check_model().prior._broadcast(map_theta.size)
        if getattr(estimator, "session_swap", None) is None:
            theta, diagnostics, cov = _draw(value_and_grad, map_theta, 1.0 / std**2, n_samples,
                                            **draw)
            components: tuple[SwapComponent, ...] = ()
        else:
            theta, diagnostics, components = _draw_swap_readings(
                estimator, demonstrations, map_theta, 1.0 / std**2, n_samples, draw)
            cov = _laplace_covariance(value_and_grad, map_theta, 1.0 / std**2, step)[0]
    if np.isfinite(diagnostics.max_r_hat()) and diagnostics.max_r_hat() > 1.01:
        logger.warning("the chains still disagree after %d draws each (max R-hat %.3f > "
                       "1.01): raise max_draws or n_warmup", diagnostics.n_draws,
                       diagnostics.max_r_hat())
    map_policy, *policies = _greedy_policies(mdp, np.vstack([map_theta, theta]))
    return Posterior(theta=theta, policies=np.stack(policies), map_theta=map_theta,
                     map_policy=map_policy, covariance=cov, n_actions=mdp.n_actions,
                     method=method, diagnostics=diagnostics, components=components)
