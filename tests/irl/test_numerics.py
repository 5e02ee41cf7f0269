"""Numerics at the extremes: the likelihoods stay finite and exact up to 1e4 times the true
weights, and the optimizers treat a non-finite objective as a failed step, never an answer."""

import warnings

import numpy as np
import pytest
from scipy.special import log_softmax

import irl
from irl.inference import posterior_stats
from irl.learners.optimize import maximize_gradient_ascent, maximize_lbfgs
from irl.solvers import OptimalQSolver
from tests.irl.conftest import (
    OM_KINDS,
    brute_force_log,
    random_demo,
    random_mdp,
    random_observation_model,
)

SCALES = (1.0, 300.0, 1e4)


def sparse_random_mdp(rng, n_states=3, n_actions=2, n_features=2) -> irl.TabularMDP:
    """A random MDP whose transitions have structural zeros (each row keeps 2 successors)."""
    T = rng.dirichlet(np.ones(n_states), size=(n_states, n_actions))
    for s in range(n_states):
        for a in range(n_actions):
            T[s, a, rng.permutation(n_states)[2:]] = 0.0
    T /= T.sum(axis=2, keepdims=True)
    phi = rng.normal(size=(n_states, n_actions, n_features))
    return irl.TabularMDP(transitions=T, features=phi, discount=0.9,
                          initial=rng.dirichlet(np.ones(n_states)))


@pytest.mark.parametrize("domain", ["forestworld", "onion_sorting"])
@pytest.mark.parametrize("scale", SCALES)
def test_every_likelihood_is_finite_up_to_1e4_times_the_true_weights(domain, scale):
    """At 300x, MMAP-BIRL and HiddenDataEM used to raise "observation ... is impossible" and
    MAP-BIRL returned -inf."""
    dom = getattr(irl.domains, domain)(noise=0.3)
    demos, _ = dom.sample(5, 15, occlusion=0.2, seed=0)
    theta = scale * dom.true_theta
    kw = {"beta": dom.beta, "prior": dom.prior}
    mmap = irl.MMAPBIRL(dom.mdp, dom.observation_model, **kw)
    map_ = irl.MAPBIRL(dom.mdp, dom.observation_model, **kw)
    em = irl.HiddenDataEM(dom.mdp, dom.observation_model)
    values = [mmap.log_likelihood(theta, demos), mmap.log_posterior(theta, demos),
              map_.log_likelihood(theta, demos), em.e_step(theta, demos).log_likelihood.sum()]
    assert np.all(np.isfinite(values)), values
    for est in (mmap, map_):
        assert np.all(np.isfinite(est.log_posterior_gradient(theta, demos)))

    # MAP-BIRL's likelihood in closed form: sum over observed steps of log pi(a | s).
    log_pi = log_softmax(dom.beta * OptimalQSolver(dom.mdp).q_values(theta), axis=1)
    pairs = np.concatenate([dom.observation_model.nominal[d.as_array()[d.as_array() >= 0]]
                            for d in demos])
    assert values[2] == pytest.approx(log_pi[pairs[:, 0], pairs[:, 1]].sum(), rel=1e-12)


@pytest.mark.parametrize("kind", OM_KINDS)
@pytest.mark.parametrize("structural_zeros", [False, True])
@pytest.mark.parametrize("scale", SCALES)
@pytest.mark.parametrize("seed", range(4))
def test_mmap_likelihood_and_posterior_at_extreme_weights_equal_log_space_enumeration(
    seed, scale, structural_zeros, kind
):
    rng = np.random.default_rng(300 + seed)
    mdp = (sparse_random_mdp if structural_zeros else random_mdp)(rng, 3, 2, 2)
    om = random_observation_model(rng, 3, 2, n_obs=4, kind=kind)
    demos = [random_demo(rng, 4, 4), random_demo(rng, 3, 4)]
    theta = scale * rng.normal(size=2)
    log_pi = log_softmax(OptimalQSolver(mdp).q_values(theta), axis=1)
    oracle = [brute_force_log(mdp, log_pi, om, d) for d in demos]
    if not np.all(np.isfinite([ll for ll, _ in oracle])):
        pytest.skip("the random demonstration is impossible under this MDP")
    est = irl.MMAPBIRL(mdp, om, beta=1.0)
    assert est.log_likelihood(theta, demos) == pytest.approx(sum(ll for ll, _ in oracle),
                                                             rel=1e-10)
    for method in ("auto", "log"):
        stats = posterior_stats(mdp, log_pi, demos, om, method=method)
        for i, (ll, marg) in enumerate(oracle):
            assert stats.log_likelihood[i] == pytest.approx(ll, rel=1e-10)
            np.testing.assert_allclose(stats.occupancy[i], marg.sum(axis=0), atol=1e-10)
            np.testing.assert_allclose(stats.initial[i], marg[0].sum(axis=1), atol=1e-10)


@pytest.mark.parametrize("cls", [irl.MMAPBIRL, irl.MAPBIRL])
def test_fit_from_1e4_times_the_true_weights_reaches_the_usual_optimum(cls):
    """A start where the policy is deterministic to within e^-1000 used to stop the fit with
    "observation ... is impossible"; now it climbs to the optimum a default start finds."""
    dom = irl.domains.forestworld(noise=0.3)
    demos, _ = dom.sample(5, 15, occlusion=0.2, seed=0)
    kw = {"beta": dom.beta, "prior": dom.prior, "tol": 1e-9}
    usual = cls(dom.mdp, dom.observation_model, **kw).fit(demos)
    far = cls(dom.mdp, dom.observation_model, init=1e4 * dom.true_theta, **kw).fit(demos)
    assert far.converged_
    assert far.log_posterior_ == pytest.approx(usual.log_posterior_, abs=1e-4)
    np.testing.assert_allclose(far.theta_, usual.theta_, atol=5e-3)


# -- the optimizers -------------------------------------------------------------------------

def boxed(x):
    """Maximize ``-(x - 5)^2`` where it is defined (x <= 3): the best finite point is x = 3."""
    if x[0] > 3.0:
        return -np.inf, np.zeros(1)
    return -(x[0] - 5.0) ** 2, np.array([-2.0 * (x[0] - 5.0)])


def test_lbfgs_treats_a_non_finite_value_as_a_failed_step():
    """Given inf, scipy's L-BFGS-B alone stops at x = 1 and reports convergence (measured with
    scipy 1.17); the guarded search backs off and reaches the edge of the finite region."""
    with pytest.warns(irl.ConvergenceWarning, match="not finite at [0-9]+ trial point"):
        res = maximize_lbfgs(boxed, [np.array([0.0])])
    assert res.theta[0] == pytest.approx(3.0, abs=1e-3)
    assert res.value == pytest.approx(boxed(res.theta)[0])
    assert np.isfinite(res.value) and res.n_failed_steps > 0
    assert not res.converged
    assert all(np.isfinite(h["value"]) for h in res.history)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_lbfgs_never_returns_a_non_finite_point(bad):
    def f(x):
        if abs(x[0]) > 2.0:
            return bad, np.zeros(1)
        return -(x[0] - 1.0) ** 2, np.array([-2.0 * (x[0] - 1.0)])

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", irl.ConvergenceWarning)
        res = maximize_lbfgs(f, [np.array([-1.9])])
    assert res.theta[0] == pytest.approx(1.0, abs=1e-4)
    assert res.value == pytest.approx(0.0, abs=1e-8)


def test_gradient_ascent_halves_its_step_after_a_failed_one():
    res = maximize_gradient_ascent(boxed, [np.array([0.0])], step_size=0.4, decay=1.0,
                                   max_iter=200, threshold=1e-6)
    assert res.n_failed_steps > 0
    assert 2.99 < res.theta[0] <= 3.0
    assert res.value == pytest.approx(boxed(res.theta)[0])


@pytest.mark.parametrize("optimizer", [maximize_lbfgs, maximize_gradient_ascent])
def test_a_start_where_the_objective_is_not_finite_is_a_clear_error(optimizer):
    with pytest.raises(ValueError, match=r"finite at every start; at start 1 .* init"):
        optimizer(boxed, [np.array([0.0]), np.array([4.0])])
