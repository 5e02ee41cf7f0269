import numpy as np
import pytest

import irl
from irl.solvers import OptimalQSolver
from tests.irl.conftest import brute_force, random_demo, random_mdp, random_observation_model


def finite_difference(f, theta, eps=1e-6):
    grad = np.zeros_like(theta)
    for k in range(theta.size):
        e = np.zeros_like(theta)
        e[k] = eps
        grad[k] = (f(theta + e) - f(theta - e)) / (2 * eps)
    return grad


def same_region(mdp, theta, eps):
    solver = OptimalQSolver(mdp)
    ref = solver.solve(theta).policy
    return all(
        np.array_equal(OptimalQSolver(mdp).solve(theta + s * eps * np.eye(theta.size)[k]).policy,
                       ref)
        for k in range(theta.size) for s in (-1, 1)
    )


@pytest.mark.parametrize("sparse", [False, True])
@pytest.mark.parametrize("seed", range(8))
def test_log_likelihood_equals_enumeration_and_gradient_finite_differences(seed, sparse):
    rng = np.random.default_rng(100 + seed)
    mdp = random_mdp(rng, n_states=3, n_actions=2, n_features=3, sparse=sparse)
    om = random_observation_model(rng, 3, 2, n_obs=5)
    demos = [random_demo(rng, 4, 5), random_demo(rng, 3, 5), random_demo(rng, 4, 5)]
    theta = rng.normal(size=3)
    if not same_region(mdp, theta, 1e-6):
        pytest.skip("theta lies on a boundary between greedy policies")
    est = irl.MMAPBIRL(mdp, om, beta=1.3, prior=irl.GaussianPrior(mean=-1.0, std=0.7))

    pi = irl.solvers.boltzmann_policy(OptimalQSolver(mdp).q_values(theta), 1.3)
    dense = random_mdp(np.random.default_rng(100 + seed), 3, 2, 3) if sparse else mdp
    expected = sum(brute_force(dense, pi, om, d)[0] for d in demos)
    assert est.log_likelihood(theta, demos) == pytest.approx(expected, rel=1e-10)

    fd = finite_difference(lambda th: est.log_likelihood(th, demos), theta)
    np.testing.assert_allclose(est.log_likelihood_gradient(theta, demos), fd, rtol=1e-5,
                               atol=1e-7)
    fd_post = finite_difference(lambda th: est.log_posterior(th, demos), theta)
    np.testing.assert_allclose(est.log_posterior_gradient(theta, demos), fd_post, rtol=1e-5,
                               atol=1e-7)


def test_prior_gradient_is_the_true_gaussian_gradient():
    prior = irl.GaussianPrior(mean=[-1.0, 0.5], std=[0.7, 2.0])
    theta = np.array([0.3, -1.2])
    fd = finite_difference(prior.log_prob, theta)
    np.testing.assert_allclose(prior.grad_log_prob(theta), fd, rtol=1e-7)
    np.testing.assert_allclose(prior.grad_log_prob(theta), -(theta - [-1, 0.5]) / [0.49, 4.0])


@pytest.mark.parametrize("seed", range(4))
def test_identity_model_without_occlusion_is_map_birl(seed):
    dom = irl.domains.forestworld(noise=0.0)
    mdp = dom.mdp
    om = irl.identity_observation_model(mdp.n_states, mdp.n_actions)
    _, trajs = dom.sample(6, 12, occlusion=0.0, seed=seed)
    demos = [irl.Demonstration.from_pairs(t.states, t.actions, mdp.n_actions) for t in trajs]
    mmap = irl.MMAPBIRL(mdp, om, beta=dom.beta, prior=dom.prior, seed=0)
    map_ = irl.MAPBIRL(mdp, om, beta=dom.beta, prior=dom.prior, seed=0)
    rng = np.random.default_rng(seed)
    offsets = []
    for _ in range(4):
        theta = rng.normal(size=3) * 2
        np.testing.assert_allclose(
            mmap.log_likelihood_gradient(theta, demos),
            map_.log_likelihood_gradient(theta, demos), rtol=1e-9, atol=1e-9,
        )
        offsets.append(mmap.log_likelihood(theta, demos) - map_.log_likelihood(theta, demos))
    # The difference is log p0 + sum log T: the same for every theta.
    np.testing.assert_allclose(offsets, offsets[0], rtol=1e-10)
    # Fitted tightly, both find the same maximum (their objectives differ by a constant) at the
    # same weights. Where the maximum sits on a boundary between greedy policies (seed 2), the
    # posterior is flat to 1e-9 over 5e-5 in theta, so the weights agree to 1e-4.
    mmap.tol = map_.tol = 1e-13
    mmap.max_iter = map_.max_iter = 1000
    mmap.fit(demos)
    map_.fit(demos)
    assert mmap.log_posterior_ - offsets[0] == pytest.approx(map_.log_posterior_, abs=1e-8)
    np.testing.assert_allclose(mmap.theta_, map_.theta_, rtol=1e-4)


def test_fit_recovers_forestworld_policy():
    dom = irl.domains.forestworld(noise=0.3)
    demos, _ = dom.sample(10, 15, occlusion=0.2, seed=3)
    est = irl.MMAPBIRL(dom.mdp, dom.observation_model, beta=dom.beta, prior=dom.prior, seed=0)
    assert est.fit(demos) is est
    assert est.theta_.shape == (3,)
    assert est.policy_.shape == (16,)
    assert est.n_iter_ > 0 and est.history_
    assert est.theta_[2] > 0 > max(est.theta_[0], est.theta_[1])
    assert irl.normalized_inverse_learning_error(dom.mdp, dom.true_theta, est.theta_) < 1.0


def test_paper_gradient_ascent_improves_the_posterior():
    dom = irl.domains.forestworld(noise=0.3)
    demos, _ = dom.sample(5, 15, occlusion=0.2, seed=4)
    est = irl.MMAPBIRL(dom.mdp, dom.observation_model, beta=dom.beta, prior=dom.prior,
                       optimizer="gradient-ascent", n_restarts=1, max_iter=300)
    est.fit(demos)
    start = est.log_posterior(np.full(3, -1.0), demos)
    assert est.log_posterior_ > start
    assert est.history_[0]["value"] <= est.log_posterior_


def test_gradient_is_cached_per_greedy_policy():
    dom = irl.domains.onion_sorting(noise=0.3)
    demos, _ = dom.sample(4, 15, occlusion=0.2, seed=0)
    est = irl.MMAPBIRL(dom.mdp, dom.observation_model, beta=dom.beta, prior=dom.prior, seed=0)
    est.fit(demos)
    solver = est._solver
    # One solve per objective evaluation, plus the fitted policy's...
    assert solver.n_solves_ + solver.n_reuses_ == len(est.history_) + 1
    # ... of which only a few ran policy iteration; the rest reused a cached dQ,
    assert 0 < solver.n_solves_ <= (solver.n_solves_ + solver.n_reuses_) // 3
    # which is the dQ a fresh solve computes.
    fresh = OptimalQSolver(dom.mdp).solve(est.theta_)
    np.testing.assert_array_equal(solver.solve(est.theta_).policy, fresh.policy)
    np.testing.assert_allclose(solver.solve(est.theta_).dQ, fresh.dQ, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_the_value_only_log_posterior_is_the_value_of_the_one_with_a_gradient(backend):
    """log_posterior_value_function gives the value of log_posterior_function (and of
    log_posterior) without the gradient's product: the same number at thetas across several
    greedy policies, with and without a session swap, and for MAP-BIRL, on either backend."""
    if backend == "numba":
        pytest.importorskip("numba")
    from irl.observation.swap import value_swap

    dom = irl.domains.onion_sorting(noise=0.3)
    demos, _ = dom.sample(n=3, length=15, occlusion=0.2, seed=4)
    swap = value_swap(dom.task, "prediction", ("good", "bad"), 0.1)
    kw = {"beta": dom.beta, "prior": dom.prior}
    identity = irl.identity_observation_model(dom.mdp.n_states, dom.mdp.n_actions)
    _, trajs = dom.sample(n=3, length=15, seed=4)
    seen = [irl.Demonstration.from_pairs(t.states, t.actions, dom.mdp.n_actions) for t in trajs]
    estimators = [
        (irl.MMAPBIRL(dom.mdp, dom.observation_model, backend=backend, **kw), demos),
        (irl.MMAPBIRL(dom.mdp, dom.observation_model, backend=backend, session_swap=swap,
                      **kw), demos),
        (irl.MAPBIRL(dom.mdp, identity, **kw), seen)]
    thetas = np.random.default_rng(5).normal(scale=2.0, size=(12, dom.mdp.n_features))
    for est, data in estimators:
        value_and_grad = est.log_posterior_function(data)
        value = est.log_posterior_value_function(data)
        policies = {OptimalQSolver(dom.mdp).solve(t).policy.tobytes() for t in thetas}
        assert len(policies) > 3  # the thetas cross several greedy policies
        for t in thetas:
            v = value(t)
            assert isinstance(v, float)
            np.testing.assert_allclose(v, value_and_grad(t)[0], rtol=0, atol=1e-10)
            np.testing.assert_allclose(v, est.log_posterior(t, data), rtol=0, atol=1e-10)
