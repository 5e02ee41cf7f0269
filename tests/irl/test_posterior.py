"""irl.posterior against exact answers: quadrature of the exact log posterior, the prior where
the demonstrations say nothing, irl.metrics' ILE, and ArviZ's chain diagnostics."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import irl
from irl.posterior import (
    Posterior,
    expected_regret,
    load_posterior,
    map_policy_risk,
    sample_posterior,
)
from irl.solvers import OptimalQSolver
from irl.stats import effective_sample_size, split_rhat
from tests.irl.conftest import OM_KINDS, random_observation_model


def two_state_mdp() -> irl.TabularMDP:
    """Two states, two actions, one weight: action 0 earns theta in state 0 and -theta/2 in
    state 1, so which action is greedy depends on theta's sign and size."""
    T = np.array([[[0.8, 0.2], [0.3, 0.7]], [[0.5, 0.5], [0.1, 0.9]]])
    phi = np.array([[[1.0], [0.0]], [[-0.5], [0.0]]])
    return irl.TabularMDP(transitions=T, features=phi, discount=0.9, initial=[0.5, 0.5])


def noisy_two_state_problem(seed=0, occluded=0.3):
    mdp = two_state_mdp()
    om = irl.ObservationModel(np.array(
        [[[0.7, 0.1, 0.1, 0.1], [0.1, 0.7, 0.1, 0.1]],
         [[0.1, 0.1, 0.7, 0.1], [0.1, 0.1, 0.1, 0.7]]]))
    rng = np.random.default_rng(seed)
    demos = [irl.Demonstration([None if rng.random() < occluded else int(o)
                                for o in rng.choice(4, size=8, p=[0.4, 0.1, 0.2, 0.3])])
             for _ in range(2)]
    est = irl.MMAPBIRL(mdp, om, beta=1.0, prior=irl.GaussianPrior(0.0, 2.0))
    return mdp, est, demos


def sorting_posterior(seed: int, n_samples: int, noise: float = 0.45):
    """The domain and the Laplace posterior of MMAP-BIRL on two short sorting demonstrations."""
    dom = irl.domains.onion_sorting(noise=noise)
    demos, _ = dom.sample(n=2, length=10, occlusion=0.2, seed=seed)
    est = irl.MMAPBIRL(dom.mdp, dom.observation_model, beta=dom.beta, prior=dom.prior)
    return dom, sample_posterior(est, demos, n_samples=n_samples, seed=0, method="laplace")


def quadrature(est, demos, lo=-12.0, hi=12.0, n=2001):
    """The exact posterior of the single weight on a grid: its density and the grid."""
    grid = np.linspace(lo, hi, n)
    logp = np.array([est.log_posterior(np.array([t]), demos) for t in grid])
    dens = np.exp(logp - logp.max())
    dens /= np.trapezoid(dens, grid)
    return grid, dens


def test_mcmc_samples_match_the_exact_posterior_by_quadrature():
    mdp, est, demos = noisy_two_state_problem()
    post = sample_posterior(est, demos, n_samples=2000, seed=1, method="mcmc")
    grid, dens = quadrature(est, demos)
    mean = np.trapezoid(grid * dens, grid)
    sd = np.sqrt(np.trapezoid((grid - mean) ** 2 * dens, grid))
    draws = post.theta[:, 0]
    se = sd / np.sqrt(post.diagnostics.ess[0])
    assert abs(draws.mean() - mean) < 4 * se
    assert abs(draws.std() - sd) < 0.1 * sd
    cdf = np.concatenate([[0.0], np.cumsum((dens[1:] + dens[:-1]) / 2 * np.diff(grid))])
    ks = stats.kstest(draws, lambda x: np.interp(x, grid, cdf)).statistic
    assert ks < 0.06
    # the confidence is the posterior mass of the region where each action is greedy
    solver = OptimalQSolver(mdp)
    greedy = np.stack([solver.solve(np.array([t])).policy for t in grid])  # (grid, S)
    for s in range(2):
        for a in range(2):
            mass = np.trapezoid(dens * (greedy[:, s] == a), grid)
            assert abs(post.action_confidence()[s, a] - mass) < 0.05
    assert post.diagnostics.max_r_hat() < 1.02 and post.diagnostics.n_divergent == 0


@pytest.mark.parametrize("method", ["laplace", "mcmc"])
def test_demonstrations_that_show_nothing_leave_the_prior(method):
    mdp = two_state_mdp()
    om = irl.identity_observation_model(2, 2)
    prior = irl.GaussianPrior(1.5, 0.8)
    est = irl.MMAPBIRL(mdp, om, beta=1.0, prior=prior)
    demos = [irl.Demonstration([None] * 5)]
    post = sample_posterior(est, demos, n_samples=2000, seed=3, method=method)
    np.testing.assert_allclose(post.map_theta, [1.5], atol=1e-5)
    np.testing.assert_allclose(post.covariance, [[0.8**2]], rtol=1e-4)
    assert abs(post.theta.mean() - 1.5) < 4 * 0.8 / np.sqrt(post.diagnostics.ess[0])
    assert abs(post.theta.std() - 0.8) < 0.06
    # P(theta > 0) under N(1.5, 0.8^2)
    assert abs(post.action_confidence()[0, 0] - stats.norm.sf(0, 1.5, 0.8)) < 0.03


def test_laplace_covariance_is_minus_the_inverse_hessian():
    _mdp, est, demos = noisy_two_state_problem(seed=4)
    post = sample_posterior(est, demos, n_samples=10, method="laplace")
    t, h = post.map_theta[0], 1e-3
    f = [est.log_posterior(np.array([t + d]), demos) for d in (-h, 0.0, h)]
    curvature = (f[0] - 2 * f[1] + f[2]) / h**2
    np.testing.assert_allclose(post.covariance[0, 0], -1.0 / curvature, rtol=1e-3)


@pytest.mark.parametrize("kind", OM_KINDS)
@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_every_observation_model_and_backend(kind, backend):
    if backend == "numba":
        pytest.importorskip("numba")
    rng = np.random.default_rng(7)
    dom = irl.domains.onion_sorting(noise=0.3)
    om = random_observation_model(rng, dom.mdp.n_states, dom.mdp.n_actions, n_obs=6, kind=kind)
    demos, _ = dom.sample(n=2, length=6, occlusion=0.3, seed=2, observation_model=om)
    est = irl.MMAPBIRL(dom.mdp, om, beta=dom.beta, prior=dom.prior, backend=backend)
    post = sample_posterior(est, demos, n_samples=50, seed=0, method="laplace")
    assert post.theta.shape == (50, 6) and np.all(np.isfinite(post.theta))
    np.testing.assert_allclose(post.action_confidence().sum(axis=1), 1.0)
    # centred on this model's MAP, and the same draws as the numpy reference
    np.testing.assert_allclose(post.map_theta, est.fit(demos).theta_, atol=1e-4)
    reference = irl.MMAPBIRL(dom.mdp, om, beta=dom.beta, prior=dom.prior, backend="numpy")
    np.testing.assert_allclose(
        post.theta, sample_posterior(reference, demos, n_samples=50, seed=0,
                                     method="laplace").theta, rtol=1e-5, atol=1e-6)


def test_confidence_rows_sum_to_one_and_credible_sets_are_the_fewest_actions():
    _, post = sorting_posterior(seed=5, n_samples=400)
    conf = post.action_confidence()
    assert conf.shape == (48, 5)
    np.testing.assert_allclose(conf.sum(axis=1), 1.0)
    assert np.all(post.map_confidence() == conf[np.arange(48), post.map_policy])
    for level in (0.5, 0.9):
        for s, actions in enumerate(post.credible_actions(level)):
            covered = conf[s, list(actions)].sum()
            assert covered >= level - 1e-12
            assert conf[s, list(actions[:-1])].sum() < level  # one fewer would not do
    assert any(len(a) > 1 for a in post.credible_actions(0.9))  # little data: some doubt


@pytest.mark.parametrize("method", ["laplace", "mcmc"])
def test_a_seed_reproduces_the_samples(method):
    _mdp, est, demos = noisy_two_state_problem(seed=2)
    kw = {"n_samples": 200, "method": method, "n_draws": 60, "n_warmup": 30, "max_draws": 60}
    a = sample_posterior(est, demos, seed=11, **kw)
    b = sample_posterior(est, demos, seed=11, **kw)
    c = sample_posterior(est, demos, seed=12, **kw)
    np.testing.assert_array_equal(a.theta, b.theta)
    assert not np.array_equal(a.theta, c.theta)


def test_a_fitted_estimators_map_and_policy_are_the_ones_the_confidence_is_about():
    """The policy the robot runs (the fitted estimator's) is the one the confidence scores,
    even where another optimizer's run would stop a rounding away, across a policy border."""
    dom = irl.domains.onion_sorting(noise=0.45)
    demos, _ = dom.sample(n=2, length=10, occlusion=0.2, seed=5)
    est = irl.MMAPBIRL(dom.mdp, dom.observation_model, beta=dom.beta, prior=dom.prior)
    est.fit(demos)
    before = est.theta_.copy()
    post = sample_posterior(est, demos, n_samples=50, method="laplace")
    np.testing.assert_array_equal(est.theta_, before)  # left as it was
    np.testing.assert_array_equal(post.map_theta, est.theta_)
    np.testing.assert_array_equal(post.map_policy, est.policy_)
    unfitted = irl.MMAPBIRL(dom.mdp, dom.observation_model, beta=dom.beta, prior=dom.prior)
    again = sample_posterior(unfitted, demos, n_samples=50, method="laplace")
    assert not hasattr(unfitted, "theta_")
    np.testing.assert_allclose(again.map_theta, est.theta_, atol=1e-4)


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"n_samples": 0}, "n_samples must be"),
    ({"n_samples": 2.5}, "n_samples must be"),
    ({"method": "nuts"}, "method must be one of ('laplace', 'mcmc'); got 'nuts'"),
    ({"n_chains": 1}, "n_chains must be"),
])
def test_bad_arguments_get_one_line_that_names_them(kwargs, message):
    _mdp, est, demos = noisy_two_state_problem()
    with pytest.raises((ValueError, TypeError)) as info:
        sample_posterior(est, demos, **kwargs)
    assert message in str(info.value) and "\n" not in str(info.value)


def test_only_bayesian_learners_have_a_posterior():
    dom = irl.domains.onion_sorting()
    demos, _ = dom.sample(n=1, length=5, seed=0)
    with pytest.raises(TypeError, match=r"estimator must be an irl\.MMAPBIRL or irl\.MAPBIRL"):
        sample_posterior(irl.HiddenDataEM(dom.mdp, dom.observation_model), demos)


def test_the_map_policy_risk_is_the_ile_under_each_sample():
    dom, post = sorting_posterior(seed=8, n_samples=60)
    risk = map_policy_risk(post, dom.mdp)
    expected = [irl.inverse_learning_error(dom.mdp, t, post.map_theta) for t in post.theta]
    np.testing.assert_allclose(risk.ile, expected, rtol=1e-7, atol=1e-7)
    same = np.all(post.policies == post.map_policy, axis=1)
    assert np.all(risk.optimal[same])  # the same greedy policy is optimal by definition
    assert 0.0 < risk.p_optimal < 1.0 and risk.expected_ile > 0.0


def test_expected_regret_is_zero_where_every_sample_agrees():
    dom, post = sorting_posterior(seed=9, n_samples=80)
    regret = expected_regret(post, dom.mdp)
    solver = OptimalQSolver(dom.mdp)
    Q = np.stack([solver.q_values(t) for t in post.theta])
    direct = (Q.max(axis=2) - Q[:, np.arange(48), post.map_policy]).mean(axis=0)
    np.testing.assert_allclose(regret, direct, rtol=1e-7, atol=1e-9)
    sure = post.map_confidence() == 1.0
    assert np.all(regret[sure] < 1e-9) and np.all(regret[~sure] > 0)


def test_a_posterior_file_round_trips_and_a_wrong_file_is_one_line(tmp_path):
    _mdp, est, demos = noisy_two_state_problem()
    post = sample_posterior(est, demos, n_samples=50, seed=0, method="mcmc", n_draws=40,
                            n_warmup=20)
    back = load_posterior(post.save(tmp_path / "posterior.npz"))
    assert isinstance(back, Posterior)
    np.testing.assert_array_equal(back.theta, post.theta)
    np.testing.assert_array_equal(back.action_confidence(), post.action_confidence())
    assert back.diagnostics.to_dict() == post.diagnostics.to_dict()
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="is not a posterior file") as info:
        load_posterior(tmp_path / "bad.npz")
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("shape", [(4, 100), (4, 101), (3, 9), (8, 40)])
def test_chain_diagnostics_equal_arviz(shape):
    az = pytest.importorskip("arviz")
    rng = np.random.default_rng(sum(shape))
    x = rng.standard_normal(shape).cumsum(axis=1) * 0.3 + rng.standard_normal((shape[0], 1))
    assert split_rhat(x) == pytest.approx(float(az.rhat(x)), abs=1e-12)
    assert effective_sample_size(x) == pytest.approx(float(az.ess(x)), rel=1e-10)


def test_chains_that_disagree_have_a_large_rhat_and_few_effective_draws():
    rng = np.random.default_rng(0)
    agree = rng.standard_normal((4, 500))
    apart = agree + np.arange(4)[:, None]
    assert split_rhat(agree) < 1.01 and split_rhat(apart) > 1.5
    assert effective_sample_size(agree) > 1500 and effective_sample_size(apart) < 100


def test_map_birl_has_mmap_birls_posterior_where_nothing_is_hidden():
    """With the identity observation model and no occlusion the two learners' log posteriors
    differ by a constant: the same seed gives the same draws."""
    mdp = two_state_mdp()
    om = irl.identity_observation_model(2, 2)
    rng = np.random.default_rng(0)
    demos = [irl.Demonstration(rng.integers(0, 4, size=12).tolist()) for _ in range(2)]
    kw = {"beta": 1.0, "prior": irl.GaussianPrior(0.0, 2.0)}
    posts = [sample_posterior(cls(mdp, om, **kw), demos, n_samples=300, seed=4, method=m,
                              n_draws=100, n_warmup=50)
             for m in ("laplace", "mcmc") for cls in (irl.MMAPBIRL, irl.MAPBIRL)]
    np.testing.assert_allclose(posts[1].theta, posts[0].theta, rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(posts[3].theta, posts[2].theta, rtol=1e-6, atol=1e-6)


def test_chains_that_disagree_are_extended_up_to_max_draws():
    _mdp, est, demos = noisy_two_state_problem(seed=3)
    short = sample_posterior(est, demos, n_samples=20, seed=0, n_draws=8, n_warmup=20,
                             max_draws=8)
    assert short.diagnostics.n_draws == 8 and short.diagnostics.max_r_hat() > 1.01
    longer = sample_posterior(est, demos, n_samples=20, seed=0, n_draws=8, n_warmup=20,
                              max_draws=40)
    assert longer.diagnostics.n_draws > 8 and longer.diagnostics.n_draws <= 40
    assert longer.diagnostics.n_gradients > short.diagnostics.n_gradients
    assert longer.diagnostics.n_draws == 40 or longer.diagnostics.max_r_hat() <= 1.01


def test_reachable_states_are_those_some_actions_reach():
    mdp = two_state_mdp()
    assert mdp.reachable_states().tolist() == [True, True]
    T = np.array([[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0]],
                  [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]])
    island = irl.TabularMDP(transitions=T, features=np.zeros((3, 2, 1)), discount=0.9,
                            initial=[1.0, 0.0, 0.0])
    assert island.reachable_states().tolist() == [True, True, False]
    reach = irl.domains.onion_sorting().mdp.reachable_states()
    assert reach.sum() == 10  # the sorter's loop; a held onion is where the gripper is
