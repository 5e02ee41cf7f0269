import numpy as np
import pytest

import irl
from irl.learners.maxent import (
    expected_feature_counts,
    mce_dual,
    observed_segments,
    soft_backward,
    time_indexed,
)
from tests.irl.conftest import brute_force, random_demo, random_mdp, random_observation_model


@pytest.mark.parametrize("seed", range(5))
def test_e_step_equals_brute_force_posterior(seed):
    rng = np.random.default_rng(200 + seed)
    mdp = random_mdp(rng, n_states=3, n_actions=2, n_features=2)
    om = random_observation_model(rng, 3, 2, n_obs=4)
    demos = [random_demo(rng, 4, 4), random_demo(rng, 3, 4)]
    theta = rng.normal(size=2)
    est = irl.HiddenDataEM(mdp, om)
    stats = est.e_step(theta, demos)
    log_pi, _ = soft_backward(mdp, mdp.reward(theta), 4)
    for i, d in enumerate(demos):
        ll, marg = brute_force(mdp, time_indexed(log_pi, len(d)), om, d)
        assert stats.log_likelihood[i] == pytest.approx(ll, rel=1e-10)
        np.testing.assert_allclose(stats.occupancy[i], marg.sum(axis=0), atol=1e-10)
        np.testing.assert_allclose(stats.initial[i], marg[0].sum(axis=1), atol=1e-10)


def test_soft_policy_is_normalized_and_counts_match_enumeration(rng):
    mdp = random_mdp(rng, n_states=3, n_actions=2, n_features=2)
    log_pi, _ = soft_backward(mdp, mdp.reward(rng.normal(size=2)), 3)
    np.testing.assert_allclose(np.exp(log_pi).sum(axis=2), 1.0)
    D0 = mdp.initial
    # Enumerate all length-3 trajectories under the soft policy.
    import itertools

    pis = time_indexed(log_pi, 3)
    counts = np.zeros(2)
    for seq in itertools.product(range(6), repeat=3):
        s, a = [x // 2 for x in seq], [x % 2 for x in seq]
        p = D0[s[0]]
        for t in range(3):
            p *= pis[t, s[t], a[t]]
            if t < 2:
                p *= mdp.transitions[s[t], a[t], s[t + 1]]
        counts += p * sum(mdp.features[s[t], a[t]] for t in range(3))
    np.testing.assert_allclose(expected_feature_counts(mdp, log_pi, D0, 3), counts, atol=1e-12)


def test_mce_dual_gradient_finite_differences(rng):
    mdp = random_mdp(rng, n_states=4, n_actions=3, n_features=3)
    groups = {3: (rng.random(4), rng.normal(size=3)), 5: (rng.random(4), rng.normal(size=3))}
    theta = rng.normal(size=3)
    _, grad = mce_dual(mdp, theta, groups, l2=0.1)
    eps = 1e-6
    fd = [(mce_dual(mdp, theta + e, groups, 0.1)[0] - mce_dual(mdp, theta - e, groups, 0.1)[0])
          / (2 * eps) for e in np.eye(3) * eps]
    np.testing.assert_allclose(grad, fd, rtol=1e-6, atol=1e-8)


def test_observed_segments_split_at_occlusions():
    dom = irl.domains.forestworld(noise=0.0)
    A = dom.mdp.n_actions
    demo = irl.Demonstration.from_pairs([0, 1, 2, 6, 7], [0, 0, 1, 0, 0], A,
                                        occluded=[False, False, True, False, False])
    groups = observed_segments([demo], dom.mdp, dom.observation_model)
    assert set(groups) == {2}
    D0, _ = groups[2]
    assert D0[0] == 1 and D0[6] == 1


@pytest.mark.parametrize("cls", [irl.HiddenDataEM, irl.MaxEntIRL])
def test_maxent_learners_recover_forestworld_policy(cls):
    dom = irl.domains.forestworld(noise=0.0)
    demos, _ = dom.sample(10, 15, occlusion=0.0, seed=5)
    est = cls(dom.mdp, dom.observation_model).fit(demos)
    assert est.theta_[2] > 0 > max(est.theta_[:2])
    assert irl.normalized_inverse_learning_error(dom.mdp, dom.true_theta, est.theta_) < 1.0


def test_hidden_data_em_equals_maxent_without_occlusion_or_noise():
    dom = irl.domains.forestworld(noise=0.0)
    demos, _ = dom.sample(6, 10, occlusion=0.0, seed=6)
    em = irl.HiddenDataEM(dom.mdp, dom.observation_model, tol=1e-9).fit(demos)
    me = irl.MaxEntIRL(dom.mdp, dom.observation_model).fit(demos)
    # With every step observed exactly, the E-step is the data: one M-step is MaxEnt IRL.
    np.testing.assert_allclose(em.theta_, me.theta_, rtol=1e-4, atol=1e-4)


def test_hidden_data_em_warns_when_it_hits_max_iter():
    dom = irl.domains.forestworld(noise=0.3)
    demos, _ = dom.sample(4, 10, occlusion=0.4, seed=7)
    with pytest.warns(irl.ConvergenceWarning, match="max_iter=1"):
        irl.HiddenDataEM(dom.mdp, dom.observation_model, max_iter=1, tol=0.0).fit(demos)
