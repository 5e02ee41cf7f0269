"""Bootstrap intervals, learner settings, data-efficiency sweeps and their summaries."""

import dataclasses

import numpy as np
import pytest

import irl
from irl.experiments import (
    METHODS,
    PAPER_BETA,
    SweepConfig,
    Trial,
    learner_domain,
    parse_learner_setting,
    run_sweep,
    run_trial,
    sample_batch,
    summarize,
)
from irl.learners import LearnerSpec, register_learner, unregister_learner
from irl.stats import bootstrap_ci

# -- bootstrap_ci ------------------------------------------------------------------------------


def test_bootstrap_of_a_constant_sample_is_a_point():
    assert bootstrap_ci(np.full(7, 0.3), rng=0) == (0.3, 0.3)
    assert bootstrap_ci([5.0], rng=0) == (5.0, 5.0)


@pytest.mark.parametrize("seed", range(5))
def test_bootstrap_interval_contains_the_sample_statistic(seed):
    rng = np.random.default_rng(seed)
    x = rng.exponential(size=int(rng.integers(2, 40)))
    lo, hi = bootstrap_ci(x, rng=seed)
    assert lo <= x.mean() <= hi
    lo, hi = bootstrap_ci(x, np.median, rng=seed)
    assert lo <= np.median(x) <= hi
    flags = (rng.random(20) < 0.7).astype(float)
    lo, hi = bootstrap_ci(flags, rng=seed)
    assert lo <= flags.mean() <= hi
    assert lo < hi  # 20 mixed flags: a proper interval, not a point


def test_bootstrap_is_reproducible_and_narrows_with_confidence():
    x = np.random.default_rng(0).normal(size=25)
    assert bootstrap_ci(x, rng=3) == bootstrap_ci(x, rng=np.random.default_rng(3))
    lo90, hi90 = bootstrap_ci(x, confidence=0.9, rng=3)
    lo99, hi99 = bootstrap_ci(x, confidence=0.99, rng=3)
    assert lo99 <= lo90 < hi90 <= hi99


def test_bootstrap_accepts_a_statistic_without_axis():
    x = np.arange(10.0)
    lo, hi = bootstrap_ci(x, lambda v: float(v.max() - v.min()), n_resamples=300, rng=0)
    assert 0.0 <= lo <= hi <= 9.0
    # about 41% of resamples of ten draws hold both 0 and 9: the upper end is the full range,
    # and the lower end is not
    assert hi == 9.0 and lo < 9.0


def test_bootstrap_coverage_of_the_mean_is_about_nominal():
    """95% percentile intervals for the mean of N(2, 1) samples of 30 (slightly below 95% is
    the method's known small-sample behaviour)."""
    rng = np.random.default_rng(1)
    hits = sum(lo <= 2.0 <= hi for lo, hi in (
        bootstrap_ci(rng.normal(2.0, 1.0, 30), n_resamples=1000, rng=rng) for _ in range(1000)))
    assert 0.89 <= hits / 1000 <= 0.98


@pytest.mark.parametrize("kwargs, message", [
    ({"values": []}, "values must be a non-empty 1-D sample"),
    ({"values": [[1.0, 2.0]]}, "values must be a non-empty 1-D sample"),
    ({"values": [1.0, np.nan]}, "values must be finite"),
    ({"values": [1.0], "n_resamples": 0}, "n_resamples must be a positive integer; got 0"),
    ({"values": [1.0], "confidence": 1.0}, r"confidence must be in \(0, 1\); got 1.0"),
])
def test_bootstrap_bad_input(kwargs, message):
    with pytest.raises(ValueError, match=message):
        bootstrap_ci(**kwargs)


# -- learner settings --------------------------------------------------------------------------


@pytest.mark.parametrize("given, label", [
    ("x0.50", "x0.5"), ("X2", "x2"), (" paper ", "paper"), ("1.50", "1.5"), (0.75, "0.75"),
])
def test_learner_settings_are_canonical(given, label):
    assert parse_learner_setting(given) == label


@pytest.mark.parametrize("bad", ["x", "x-1", "0", "-2", "nan", "inf", "fast", "x0"])
def test_bad_learner_setting_names_the_value(bad):
    with pytest.raises(ValueError, match=f"learner_beta must be .*; got {bad!r}"):
        parse_learner_setting(bad)


def test_learner_domain_changes_only_beta():
    dom = irl.domains.onion_sorting(noise=0.3)
    assert learner_domain(dom, "x2").beta == pytest.approx(2 * dom.beta)
    assert learner_domain(dom, "0.7").beta == 0.7
    paper = learner_domain(dom, "paper")
    assert paper.beta == PAPER_BETA
    assert paper.prior is dom.prior
    assert paper.mdp is dom.mdp and paper.observation_model is dom.observation_model
    np.testing.assert_array_equal(paper.true_theta, dom.true_theta)


# -- sweep configuration and data --------------------------------------------------------------


def test_sweep_config_takes_lists_and_single_values():
    cfg = SweepConfig("sorting", ((0.2, 0.3),), methods=("maxent",), batches=2,
                      trajectories=(1, 4, 1), length=8, learners=("x1", "X1.0", "paper"))
    assert cfg.trajectories == (1, 4)
    assert cfg.length == (8,)
    assert cfg.learners == ("x1", "paper")
    assert len(cfg.trials()) == 2 * 2 * 2  # demos x batches x learners
    assert SweepConfig("sorting", ((0.2, 0.3),)).trajectories == (10,)


def test_a_sweep_runs_the_reward_learners_unless_told():
    """Registering behaviour cloning did not add it to every sweep: the library's default is
    the paper's four reward learners, as ``onionsort experiment``'s is."""
    from irl.experiments import METHODS, REWARD_METHODS

    assert SweepConfig("sorting", ((0.2, 0.3),)).methods == REWARD_METHODS
    assert REWARD_METHODS == ("mmap-birl", "map-birl", "hidden-data-em", "maxent")
    assert {"bc", "bc-em"} <= set(METHODS) - set(REWARD_METHODS)


@pytest.mark.parametrize("kwargs, message", [
    ({"trajectories": (2, 0)}, "trajectories must be integers >= 1; got 0"),
    ({"trajectories": ()}, "trajectories must have at least one value"),
    ({"length": (2.5,)}, "length must be integers >= 1; got 2.5"),
    ({"learners": ("x-1",)}, "learner_beta must be"),
    ({"learners": ()}, "learners must have at least one setting"),
])
def test_sweep_config_bad_lists(kwargs, message):
    with pytest.raises(ValueError, match=message):
        SweepConfig("sorting", ((0.2, 0.3),), **kwargs)


def test_batches_are_nested_along_the_number_of_demonstrations():
    dom = irl.domains.onion_sorting(noise=0.3)
    small = Trial("sorting", "mmap-birl", 0.2, 0.3, batch=1, trajectories=2, length=9, seed=4)
    large = dataclasses.replace(small, trajectories=5, method="maxent", learner="paper")
    a, b = sample_batch(dom, small), sample_batch(dom, large)
    assert [d.observations for d in a] == [d.observations for d in b[:2]]
    other = sample_batch(dom, dataclasses.replace(small, batch=2))
    assert [d.observations for d in a] != [d.observations for d in other]


# -- trials and summaries ----------------------------------------------------------------------


@pytest.mark.parametrize("method", METHODS)
def test_summary_intervals_and_exact_policy_rate(method):
    cfg = SweepConfig("sorting", ((0.2, 0.45),), methods=(method,), batches=3,
                      trajectories=(1, 2), length=6, learners=("x1", "x4"), seed=2)
    results = list(run_sweep(cfg))
    assert len(results) == 3 * 2 * 2
    rows = summarize(results, seed=cfg.seed)
    assert len(rows) == 2 * 2
    for row in rows:
        mine = [r for r in results if (r.trajectories, r.learner) ==
                (row["trajectories"], row["learner"])]
        assert row["batches"] == len(mine) == 3
        flags = [r.exact_policy for r in mine]
        assert set(flags) <= {0, 1}
        assert row["exact_policy_rate"] == pytest.approx(np.mean(flags))
        assert row["normalized_ile_mean"] == pytest.approx(np.mean([r.normalized_ile
                                                                    for r in mine]))
        for name, mean in (("normalized_ile", "normalized_ile_mean"),
                           ("exact_policy", "exact_policy_rate"), ("ile", "ile_mean"),
                           ("seconds", "seconds_mean")):
            assert row[f"{name}_ci_low"] <= row[mean] <= row[f"{name}_ci_high"], (name, row)
        if len(set(flags)) == 1:  # a constant sample gives the point interval
            assert row["exact_policy_ci_low"] == row["exact_policy_ci_high"] == flags[0]
        else:
            assert row["exact_policy_ci_low"] < row["exact_policy_ci_high"]
        assert row["learner_beta"] == pytest.approx(
            {"x1": 1.5, "x4": 6.0}[row["learner"]])
    assert summarize(results, seed=cfg.seed) == rows  # reproducible from the sweep seed


def test_every_method_is_run_at_every_learner_setting():
    """Learners without a beta are built the same way; their fits do not change."""
    base = Trial("sorting", "maxent", 0.2, 0.3, batch=0, trajectories=2, length=8, seed=0)
    a = run_trial(base)
    b = run_trial(dataclasses.replace(base, learner="x0.25"))
    assert (a.learner, a.learner_beta, b.learner, b.learner_beta) == ("x1", 1.5, "x0.25", 0.375)
    assert (a.ile, a.exact_policy) == (b.ile, b.exact_policy)


def test_a_fit_that_no_learner_setting_changes_is_made_once_and_stands_for_each(monkeypatch):
    import irl.experiments as experiments

    trials = [Trial("sorting", method, 0.2, 0.3, batch=0, trajectories=2, length=8, seed=0,
                    learner=learner)
              for learner in ("x1", "x0.25", "paper") for method in ("maxent", "mmap-birl")]
    ran = []
    monkeypatch.setattr(experiments, "run_trial", lambda t: ran.append(t) or run_trial(t))
    results = dict(experiments.run_trials(trials))
    # maxent has no beta: fitted once; mmap-birl at every setting
    assert [(t.method, t.learner) for t in ran] == [
        ("maxent", "x1"), ("mmap-birl", "x1"), ("mmap-birl", "x0.25"), ("mmap-birl", "paper")]
    assert sorted(results) == list(range(len(trials)))
    for i, trial in enumerate(trials):
        alone = run_trial(trial)  # what fitting it for itself gives
        assert dataclasses.replace(results[i], seconds=0.0) == \
            dataclasses.replace(alone, seconds=0.0), (trial.method, trial.learner)
    assert [results[i].learner_beta for i in (0, 2, 4)] == [1.5, 0.375, PAPER_BETA]


def test_a_learner_without_get_params_is_fitted_at_every_setting(monkeypatch):
    import irl.experiments as experiments

    spec = register_learner(LearnerSpec(
        "fixed-plain", "The true weights, whatever the beta.",
        lambda domain, *, seed=None: _Fixed(domain.true_theta)))
    ran = []
    monkeypatch.setattr(experiments, "run_trial", lambda t: ran.append(t) or run_trial(t))
    try:
        trials = [Trial("sorting", "fixed-plain", 0.0, 0.3, 0, 1, 4, 0, learner=learner)
                  for learner in ("x1", "x2")]
        assert len(list(experiments.run_trials(trials))) == len(ran) == 2
    finally:
        assert unregister_learner("fixed-plain") is spec


class _Fixed:
    """A learner that returns fixed weights (to check the scoring, not a method)."""

    def __init__(self, theta):
        self.theta = theta

    def fit(self, demos):
        self.theta_, self.n_iter_ = np.asarray(self.theta, float), 0
        return self


@pytest.mark.parametrize("sign, exact", [(1.0, 1), (-1.0, 0)])
def test_exact_policy_flag_scores_the_greedy_policy(sign, exact):
    spec = register_learner(LearnerSpec(
        "fixed-test", "The true weights times a sign.",
        lambda domain, *, seed=None: _Fixed(sign * domain.true_theta)))
    try:
        r = run_trial(Trial("sorting", "fixed-test", 0.0, 0.3, 0, 1, 4, 0))
    finally:
        assert unregister_learner("fixed-test") is spec
    assert r.exact_policy == exact
    assert (r.normalized_ile == 0.0) == bool(exact)
