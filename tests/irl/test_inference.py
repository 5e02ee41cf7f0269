import numpy as np
import pytest

import irl
from irl.inference import forward_backward, posterior_stats
from irl.solvers import boltzmann_policy
from tests.irl.conftest import (
    brute_force,
    random_demo,
    random_mdp,
    random_observation_model,
)


@pytest.mark.parametrize("sparse", [False, True])
@pytest.mark.parametrize("seed", range(6))
def test_forward_backward_equals_enumeration(seed, sparse):
    rng = np.random.default_rng(seed)
    mdp = random_mdp(rng, sparse=sparse)
    om = random_observation_model(rng, mdp.n_states, mdp.n_actions)
    pi = rng.dirichlet(np.ones(mdp.n_actions), size=mdp.n_states)
    demos = [random_demo(rng, length, om.n_observations) for length in (1, 3, 4, 4)]
    stats = posterior_stats(mdp, pi, demos, om)
    for i, d in enumerate(demos):
        dense = random_mdp(np.random.default_rng(seed)) if sparse else mdp
        ll, marg = brute_force(dense, pi, om, d)
        assert stats.log_likelihood[i] == pytest.approx(ll, rel=1e-10, abs=1e-10)
        np.testing.assert_allclose(stats.occupancy[i], marg.sum(axis=0), atol=1e-10)
        np.testing.assert_allclose(stats.initial[i], marg[0].sum(axis=1), atol=1e-10)


def test_time_varying_policy_equals_enumeration(rng):
    mdp = random_mdp(rng)
    om = random_observation_model(rng, mdp.n_states, mdp.n_actions)
    demo = random_demo(rng, 4, om.n_observations)
    pis = rng.dirichlet(np.ones(mdp.n_actions), size=(4, mdp.n_states))
    packed = demo.as_array()[None]
    stats = forward_backward(mdp, pis, packed, om.emissions)
    ll, marg = brute_force(mdp, pis, om, demo)
    assert stats.log_likelihood[0] == pytest.approx(ll, rel=1e-10)
    np.testing.assert_allclose(stats.occupancy[0], marg.sum(axis=0), atol=1e-10)


def test_all_occluded_demo_has_likelihood_one(rng):
    mdp = random_mdp(rng)
    om = random_observation_model(rng, mdp.n_states, mdp.n_actions)
    pi = rng.dirichlet(np.ones(mdp.n_actions), size=mdp.n_states)
    stats = posterior_stats(mdp, pi, [irl.Demonstration(observations=[None] * 5)], om)
    assert stats.log_likelihood[0] == pytest.approx(0.0, abs=1e-12)
    assert stats.occupancy[0].sum() == pytest.approx(5.0)


def test_ten_thousand_steps_stay_finite_and_normalized():
    dom = irl.domains.onion_sorting(noise=0.3)
    demos, _ = dom.sample(2, 10_000, occlusion=0.3, seed=1)
    pi = dom.expert_policy()
    stats = posterior_stats(dom.mdp, pi, demos, dom.observation_model)
    assert np.all(np.isfinite(stats.log_likelihood))
    assert np.all(stats.log_likelihood < -1000)  # far below float underflow if not in log space
    np.testing.assert_allclose(stats.occupancy.sum(axis=(1, 2)), 10_000, rtol=1e-9)
    assert np.all(stats.occupancy >= 0)


def test_cost_is_independent_of_occlusion_pattern(rng):
    """Occluded steps are marginalized, never enumerated: a fully occluded long demo works."""
    dom = irl.domains.onion_sorting(noise=0.3)
    pi = boltzmann_policy(np.zeros((dom.mdp.n_states, dom.mdp.n_actions)), 1.0)
    demo = irl.Demonstration(observations=[None] * 2000)
    stats = posterior_stats(dom.mdp, pi, [demo], dom.observation_model)
    assert stats.log_likelihood[0] == pytest.approx(0.0, abs=1e-9)


def test_impossible_demonstration_names_demo_and_step():
    dom = irl.domains.forestworld(noise=0.0)
    pi = dom.expert_policy()
    A = dom.mdp.n_actions
    # A fugitive cannot jump from (0, 0) to (3, 3) in one move.
    ok = irl.Demonstration.from_pairs([0, 1], [0, 0], A)
    jump = irl.Demonstration.from_pairs([0, 15], [0, 0], A)
    with pytest.raises(ValueError, match=r"demonstration 1, step 1"):
        posterior_stats(dom.mdp, pi, [ok, jump], dom.observation_model)
