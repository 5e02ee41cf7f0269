"""Behaviour cloning: the smoothed count policy at face value, EM through the observation model,
the estimator contract, and the metrics that score a policy without a reward."""

import warnings

import numpy as np
import pytest

import irl
from irl.demonstrations import observe, sample_trajectory
from irl.experiments import Trial, run_trial, sample_batch
from irl.learners.cloning import cloned_policy
from irl.metrics import (
    inverse_learning_error,
    normalized_inverse_learning_error,
    policy_mismatch,
)
from tests.irl.conftest import brute_force, random_mdp, random_observation_model

FITTED = {"theta_", "policy_", "action_probabilities_", "counts_", "fallback_",
          "unseen_states_", "n_iter_", "history_", "converged_"}


@pytest.fixture(scope="module")
def tiny():
    """3 states, 2 actions, observed noise-free as ``o = s * 2 + a``; state 2 is never seen.

    Pairs seen: (0, 1), (1, 0), occluded, (0, 1) and (1, 0), (1, 0), (0, 0), so
    ``N = [[1, 2], [3, 0], [0, 0]]`` and the actions' totals are (4, 2)."""
    mdp = random_mdp(np.random.default_rng(0), n_states=3, n_actions=2)
    demos = [irl.Demonstration([1, 2, None, 1]), irl.Demonstration([2, 2, 0])]
    return mdp, demos


def test_bc_is_the_smoothed_count_policy_of_a_hand_built_example(tiny):
    mdp, demos = tiny
    est = irl.BehaviorCloning(mdp, seed=0).fit(demos)  # identity model, alpha = 1, m uniform
    # (N(s, a) + 1 * 1/2) / (N(s) + 1)
    expected = np.array([[1.5 / 4, 2.5 / 4], [3.5 / 4, 0.5 / 4], [0.5, 0.5]])
    np.testing.assert_allclose(est.action_probabilities_, expected, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(est.counts_, [[1, 2], [3, 0], [0, 0]])
    assert est.theta_ is None and est.unseen_states_.tolist() == [2]
    assert est.policy_[:2].tolist() == [1, 0] and est.n_iter_ == 0 and est.history_ == []
    # a state never seen takes a uniformly random action: both occur over seeds
    assert {int(irl.BehaviorCloning(mdp, seed=s).fit(demos).policy_[2]) for s in range(20)} \
        == {0, 1}

    common = irl.BehaviorCloning(mdp, unseen="most-common", smoothing=2.0).fit(demos)
    m = np.array([5 / 8, 3 / 8])  # (totals + 1) / (6 + 2)
    np.testing.assert_allclose(common.fallback_, m, rtol=0, atol=1e-15)
    np.testing.assert_allclose(common.action_probabilities_, [
        [(1 + 2 * m[0]) / 5, (2 + 2 * m[1]) / 5],
        [(3 + 2 * m[0]) / 5, (0 + 2 * m[1]) / 5], m], rtol=0, atol=1e-15)
    assert common.policy_.tolist() == [1, 0, 0]  # the unseen state: the most common action


def test_no_smoothing_gives_the_empirical_frequencies_and_m_where_unseen():
    pi = cloned_policy(np.array([[1.0, 3.0], [0.0, 0.0]]), 0.0, np.array([0.5, 0.5]))
    np.testing.assert_array_equal(pi, [[0.25, 0.75], [0.5, 0.5]])


def test_face_value_reads_noisy_observations_as_their_nominal_pairs():
    dom = irl.domains.onion_sorting(noise=0.3)
    demos = sample_batch(dom, Trial("sorting", "bc", 0.2, 0.3, 0, 3, 20, 5))
    est = irl.BehaviorCloning(dom.mdp, dom.observation_model, smoothing=0.5).fit(demos)
    counts = np.zeros((dom.mdp.n_states, dom.mdp.n_actions))
    nominal = dom.observation_model.nominal
    for d in demos:
        for o in d.observations:
            if o is not None:
                counts[tuple(nominal[o])] += 1
    np.testing.assert_array_equal(est.counts_, counts)
    np.testing.assert_allclose(est.action_probabilities_.sum(axis=1), 1.0, rtol=0, atol=1e-12)


def _rollouts(mdp, om, n, length, occlusion, seed):
    rng = np.random.default_rng(seed)
    pi = rng.dirichlet(np.ones(mdp.n_actions), size=mdp.n_states)
    return [observe(sample_trajectory(mdp, pi, length, rng), om, occlusion, rng)
            for _ in range(n)]


@pytest.mark.parametrize("unseen", ["uniform", "most-common"])
def test_bc_em_equals_bc_with_a_perfect_observation_model_and_no_occlusion(unseen):
    mdp = random_mdp(np.random.default_rng(1), n_states=5, n_actions=3)
    om = irl.identity_observation_model(5, 3)
    demos = _rollouts(mdp, om, 4, 6, 0.0, seed=2)
    bc = irl.BehaviorCloning(mdp, om, unseen=unseen, seed=3).fit(demos)
    em = irl.BehaviorCloning(mdp, om, variant="em", unseen=unseen, seed=3).fit(demos)
    np.testing.assert_allclose(em.counts_, bc.counts_, rtol=0, atol=1e-12)
    np.testing.assert_allclose(em.action_probabilities_, bc.action_probabilities_, rtol=0,
                               atol=1e-12)
    np.testing.assert_array_equal(em.policy_, bc.policy_)
    assert em.converged_ and em.n_iter_ == 2  # the posterior is the data: EM stops at once


@pytest.mark.parametrize(("smoothing", "key"), [(0.0, "log_likelihood"), (1.0, "value")])
def test_bc_em_never_lowers_its_objective(smoothing, key):
    """Without smoothing the objective is the marginal likelihood of the observations; with it,
    the log posterior under the Dirichlet prior (Eq. 2). Checked at every iteration, and after
    the last M-step (the fitted policy's likelihood)."""
    rng = np.random.default_rng(4)
    mdp = random_mdp(rng, n_states=4, n_actions=3)
    om = random_observation_model(rng, 4, 3, n_obs=5)
    demos = _rollouts(mdp, om, 6, 10, 0.3, seed=5)
    est = irl.BehaviorCloning(mdp, om, variant="em", smoothing=smoothing, max_iter=60,
                              tol=0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", irl.ConvergenceWarning)
        est.fit(demos)
    values = np.array([h[key] for h in est.history_])
    assert len(values) == 60 and np.all(np.isfinite(values))
    steps = np.diff(values)
    assert steps.min() >= -1e-9 * np.abs(values).max(), steps.min()
    assert values[-1] - values[0] > 0.1  # it did climb
    if smoothing == 0.0:
        assert est.log_likelihood(demos) >= values[-1] - 1e-9


def test_bc_em_log_likelihood_is_the_exact_marginal(tiny):
    """``log P(o | pi)`` against the oracle that enumerates every hidden sequence."""
    rng = np.random.default_rng(6)
    mdp = random_mdp(rng, n_states=3, n_actions=2)
    om = random_observation_model(rng, 3, 2, n_obs=4)
    demo = irl.Demonstration([0, None, 3, 1])
    pi = rng.dirichlet(np.ones(2), size=3)
    est = irl.BehaviorCloning(mdp, om, variant="em")
    assert est.log_likelihood([demo], pi) == pytest.approx(brute_force(mdp, pi, om, demo)[0],
                                                           rel=1e-12)


def test_bc_em_learns_through_occlusion_and_noise_what_face_value_cannot():
    """Onion sorting at 45% noise: EM's policy is the expert's on the reachable states more
    often than face value's (the mechanism behind docs/results.md's table)."""
    from irl.domains.onion_sorting import reachable_states

    dom = irl.domains.onion_sorting(noise=0.45)
    states = reachable_states()
    exact = {"face-value": 0, "em": 0}
    for batch in range(4):
        demos = sample_batch(dom, Trial("sorting", "bc", 0.2, 0.45, batch, 8, 20, 77))
        for variant in exact:
            est = irl.BehaviorCloning(dom.mdp, dom.observation_model, variant=variant,
                                      seed=0).fit(demos)
            exact[variant] += policy_mismatch(dom.mdp, dom.true_theta, states=states,
                                              policy=est.policy_) == 0
    assert exact["em"] > exact["face-value"], exact


# -- the estimator contract ------------------------------------------------------------------

def test_init_stores_its_arguments_and_fit_sets_the_learned_state(tiny):
    mdp, demos = tiny
    est = irl.BehaviorCloning(mdp, variant="em", smoothing=0.5, max_iter=7)
    assert set(vars(est)) == set(est.get_params())
    assert not [a for a in dir(est) if a.endswith("_") and not a.startswith("_")]
    odd = irl.BehaviorCloning(None, "not a model", variant="nope", max_iter=-3)
    assert (odd.mdp, odd.variant, odd.max_iter) == (None, "nope", -3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", irl.ConvergenceWarning)
        assert est.fit(demos) is est
    assert {a for a in vars(est) if a.endswith("_") and not a.startswith("_")} == FITTED
    assert est.policy_.shape == (3,) and est.action_probabilities_.shape == (3, 2)


def test_sklearn_clone_and_convention_checks(tiny):
    base = pytest.importorskip("sklearn.base")
    checks = pytest.importorskip("sklearn.utils.estimator_checks")
    mdp, demos = tiny
    est = irl.BehaviorCloning(mdp, variant="em", seed=4).fit(demos)
    twin = base.clone(est)
    assert not hasattr(twin, "policy_") and repr(twin) == repr(est)
    np.testing.assert_array_equal(twin.fit(demos).policy_, est.policy_)
    fresh = irl.BehaviorCloning(mdp)
    for check in (checks.check_no_attributes_set_in_init, checks.check_get_params_invariance,
                  checks.check_parameters_default_constructible,
                  checks.check_do_not_raise_errors_in_init_or_set_params,
                  checks.check_set_params):
        check("BehaviorCloning", fresh)


BAD = [
    ("mdp", None, TypeError, r"mdp must be an irl.TabularMDP; got NoneType"),
    ("observation_model", "noise", TypeError, r"observation_model must be an irl.Observation"),
    ("variant", "dagger", ValueError, r"variant must be one of \('face-value', 'em'\); got str"),
    ("unseen", None, ValueError, r"unseen must be one of \('uniform', 'most-common'\); got"),
    ("smoothing", -1, ValueError, r"smoothing must be a finite number >= 0.0; got -1.0"),
    ("smoothing", "1", TypeError, r"smoothing must be a real number; got str '1'"),
    ("max_iter", 0, ValueError, r"max_iter must be an integer >= 1; got 0"),
    ("tol", np.nan, ValueError, r"tol must be a finite number >= 0.0; got nan"),
    ("backend", "cuda", ValueError, r"backend must be one of"),
    ("seed", -1, ValueError, r"seed must be a non-negative int; got -1"),
]


@pytest.mark.parametrize(("param", "value", "error", "message"), BAD,
                         ids=[f"{c[0]}={c[1]!r}" for c in BAD])
def test_fit_refuses_a_bad_argument_in_one_line(param, value, error, message, tiny):
    mdp, demos = tiny
    est = irl.BehaviorCloning(mdp).set_params(**{param: value})
    with pytest.raises(error, match=message) as info:
        est.fit(demos)
    assert "\n" not in str(info.value) and not hasattr(est, "policy_")


def test_bad_demonstrations_are_one_line_errors(tiny):
    mdp, _ = tiny
    with pytest.raises(ValueError, match="every step is occluded") as info:
        irl.BehaviorCloning(mdp).fit([irl.Demonstration([None, None])])
    assert "\n" not in str(info.value)
    with pytest.raises(ValueError, match="observation") as info:
        irl.BehaviorCloning(mdp).fit([irl.Demonstration([0, 99])])
    assert "\n" not in str(info.value)
    state_only = irl.state_observation_model(np.eye(3), 2)
    with pytest.raises(ValueError, match="reports no action"):
        irl.BehaviorCloning(mdp, state_only).fit([irl.Demonstration([0, 1])])
    # through the model, a state-only observation is fine
    assert irl.BehaviorCloning(mdp, state_only, variant="em").fit(
        [irl.Demonstration([0, 1, None])]).policy_.shape == (3,)
    with pytest.raises(ValueError, match=r"pi must have shape \(3, 2\)"):
        irl.BehaviorCloning(mdp, variant="em").log_likelihood(
            [irl.Demonstration([0, 1])], np.ones((2, 2)) / 2)


# -- scored by its policy ---------------------------------------------------------------------

def test_the_metrics_score_a_policy_without_a_reward():
    dom = irl.domains.onion_sorting(noise=0.3)
    mdp, theta = dom.mdp, dom.true_theta
    expert = irl.solvers.OptimalQSolver(mdp).solve(theta).policy
    assert inverse_learning_error(mdp, theta, policy=expert) == 0.0
    assert policy_mismatch(mdp, theta, policy=expert) == 0.0
    other = -theta
    greedy = irl.solvers.OptimalQSolver(mdp).solve(other).policy
    assert inverse_learning_error(mdp, theta, policy=greedy) == \
        inverse_learning_error(mdp, theta, other) > 0
    assert normalized_inverse_learning_error(mdp, theta, policy=greedy) == \
        normalized_inverse_learning_error(mdp, theta, other)
    assert policy_mismatch(mdp, theta, policy=greedy) == policy_mismatch(mdp, theta, other)
    with pytest.raises(ValueError, match="exactly one of learned_theta and policy; got both"):
        inverse_learning_error(mdp, theta, other, policy=greedy)
    with pytest.raises(ValueError, match="got neither"):
        policy_mismatch(mdp, theta)
    with pytest.raises(ValueError, match=r"policy must give one action per state"):
        inverse_learning_error(mdp, theta, policy=expert[:3])
    with pytest.raises(ValueError, match=r"policy must lie in \[0, 5\); got 7"):
        inverse_learning_error(mdp, theta, policy=np.full(mdp.n_states, 7))


def test_a_reward_is_scored_as_before_where_it_ties_two_actions():
    """A learned reward that ties actions gets its greedy policy from a solver that solved the
    expert's reward first, as the metrics always did (a fresh solver breaks the tie otherwise:
    this reward's normalized ILE is then 49.9% instead of 0)."""
    from irl.solvers import policy_values

    dom = irl.domains.onion_sorting(noise=0.3)
    trial = Trial("sorting", "maxent", 0.2, 0.3, 3, 1, 20, 0)
    theta = irl.make_estimator("maxent", dom).fit(sample_batch(dom, trial)).theta_
    solver = irl.solvers.OptimalQSolver(dom.mdp)
    reward = dom.mdp.reward(dom.true_theta)
    v_e = policy_values(dom.mdp, reward, solver.solve(dom.true_theta).policy)
    v_l = policy_values(dom.mdp, reward, solver.solve(theta).policy)
    assert inverse_learning_error(dom.mdp, dom.true_theta, theta) == np.abs(v_e - v_l).sum()
    fresh = irl.solvers.OptimalQSolver(dom.mdp).solve(theta).policy
    assert inverse_learning_error(dom.mdp, dom.true_theta, policy=fresh) > 0  # the tie


@pytest.mark.parametrize("method", ["bc", "bc-em"])
def test_a_trial_scores_cloning_by_its_policy(method):
    trial = Trial("sorting", method, 0.2, 0.3, 0, 2, 20, 11)
    result = run_trial(trial)
    dom = irl.domains.onion_sorting(noise=0.3)
    est = irl.make_estimator(method, dom, seed=trial.batch).fit(sample_batch(dom, trial))
    assert result.ile == pytest.approx(
        inverse_learning_error(dom.mdp, dom.true_theta, policy=est.policy_), rel=1e-12)
    assert result.exact_policy in (0, 1) and result.converged


def test_the_registry_builds_both_variants():
    dom = irl.domains.forestworld(noise=0.3)
    assert tuple(irl.LEARNERS)[-2:] == ("bc", "bc-em")
    face, em = (irl.make_estimator(m, dom, seed=1, backend="numpy") for m in ("bc", "bc-em"))
    assert (face.variant, em.variant) == ("face-value", "em")
    assert face.observation_model is dom.observation_model and em.seed == 1


def test_bc_em_on_the_compiled_kernels_equals_numpy():
    pytest.importorskip("numba")
    dom = irl.domains.onion_sorting(noise=0.45)
    demos = sample_batch(dom, Trial("sorting", "bc-em", 0.2, 0.45, 0, 4, 20, 21))
    fits = [irl.BehaviorCloning(dom.mdp, dom.observation_model, variant="em", backend=b,
                                seed=0).fit(demos) for b in ("numpy", "numba")]
    np.testing.assert_allclose(fits[1].action_probabilities_, fits[0].action_probabilities_,
                               rtol=0, atol=1e-9)
    assert fits[1].n_iter_ == fits[0].n_iter_
    np.testing.assert_array_equal(fits[1].policy_, fits[0].policy_)
