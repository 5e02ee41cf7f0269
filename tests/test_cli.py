"""End-to-end smoke tests of the console script on tiny configurations."""

import csv
import json

import numpy as np
import pytest

from onionsort.cli import main


def test_experiment_quick_writes_results_summary_and_plots(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["experiment", "forestworld", "--quick", "--batches", "1", "--trajectories", "3",
                 "--workers", "1", "--out", str(out)])
    assert code == 0
    rows = list(csv.DictReader((out / "results.csv").open()))
    assert rows[0].keys() >= {"method", "occlusion", "noise", "batch", "ile", "seconds"}
    assert {r["method"] for r in rows} == {"mmap-birl", "map-birl", "hidden-data-em", "maxent"}
    assert len(rows) == 4 * 4  # 4 quick points x 4 methods x 1 batch
    summary = json.loads((out / "summary.json").read_text())
    assert summary["config"]["domain"] == "forestworld"
    # one batch per point: the summary's means are the rows themselves
    by_point = {(r["method"], float(r["occlusion"]), float(r["noise"])): r for r in rows}
    for p in summary["points"]:
        row = by_point[p["method"], p["occlusion"], p["noise"]]
        assert p["ile_mean"] == pytest.approx(float(row["ile"]))
        assert p["normalized_ile_mean"] == pytest.approx(float(row["normalized_ile"]))
    for name in ("ile_vs_occlusion.png", "seconds_vs_occlusion.png", "ile_vs_noise.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not (out / "results.csv.partial").exists()
    assert "mmap-birl" in capsys.readouterr().out


def test_experiment_explicit_grid(tmp_path):
    out = tmp_path / "grid"
    main(["experiment", "sorting", "--occlusion", "0.2", "--noise", "0.3", "--batches", "1",
          "--trajectories", "2", "--length", "8", "--methods", "mmap-birl,maxent",
          "--workers", "1", "--out", str(out)])
    rows = list(csv.DictReader((out / "results.csv").open()))
    assert [(r["method"], r["occlusion"], r["noise"]) for r in rows] == [
        ("mmap-birl", "0.2", "0.3"), ("maxent", "0.2", "0.3")]


@pytest.mark.parametrize("argv, message", [
    (["experiment", "forestworld", "--methods", "svm"], "methods must be among"),
    (["experiment", "forestworld", "--occlusion", "1.5"], "occlusion must be in"),
])
def test_experiment_bad_input_is_a_clear_error(tmp_path, capsys, argv, message):
    assert main([*argv, "--out", str(tmp_path / "x")]) == 2
    assert message in capsys.readouterr().err


def test_experiment_sweeps_demonstrations_lengths_and_learner_beta(tmp_path):
    out = tmp_path / "eff"
    code = main(["experiment", "sorting", "--occlusion", "0.2", "--noise", "0.45",
                 "--trajectories", "1,2", "--length", "5,6", "--learner-beta", "x0.5,paper",
                 "--batches", "2", "--methods", "mmap-birl,maxent", "--workers", "1",
                 "--out", str(out)])
    assert code == 0
    rows = list(csv.DictReader((out / "results.csv").open()))
    assert rows[0].keys() >= {"method", "occlusion", "noise", "batch", "ile", "seconds",
                              "normalized_ile", "n_iter", "converged", "trajectories", "length",
                              "learner", "learner_beta", "exact_policy"}
    assert len(rows) == 2 * 2 * 2 * 2 * 2  # demos x lengths x learners x batches x methods
    assert {(r["trajectories"], r["length"]) for r in rows} == {
        ("1", "5"), ("1", "6"), ("2", "5"), ("2", "6")}
    assert {(r["learner"], float(r["learner_beta"])) for r in rows} == {
        ("x0.5", 0.75), ("paper", 0.03)}
    assert {r["exact_policy"] for r in rows} <= {"0", "1"}
    summary = json.loads((out / "summary.json").read_text())
    assert summary["config"]["trajectories"] == [1, 2]
    assert summary["bootstrap"]["confidence"] == 0.95
    assert len(summary["points"]) == 2 * 2 * 2 * 2
    key = ("method", "trajectories", "length", "learner")
    for p in summary["points"]:
        mine = [r for r in rows if all(str(p[k]) == r[k] for k in key)]
        assert len(mine) == 2  # the batches of this point
        # the summary is the mean of its own rows, with an interval around it
        assert p["exact_policy_rate"] == pytest.approx(
            sum(int(r["exact_policy"]) for r in mine) / len(mine))
        assert p["normalized_ile_mean"] == pytest.approx(
            sum(float(r["normalized_ile"]) for r in mine) / len(mine))
        assert p["normalized_ile_ci_low"] <= p["normalized_ile_mean"] <= p["normalized_ile_ci_high"]
        rate = p["exact_policy_rate"]
        assert 0 <= p["exact_policy_ci_low"] <= rate <= p["exact_policy_ci_high"] <= 1
    for name in ("normalized_ile_vs_demonstrations.png", "exact_policy_vs_demonstrations.png",
                 "vs_learner_beta.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("option, value, message", [
    ("--trajectories", "1,0", "--trajectories must be comma-separated integers >= 1"),
    ("--trajectories", "a,2", "--trajectories must be comma-separated integers >= 1"),
    ("--trajectories", ",", "--trajectories must list at least one value"),
    ("--length", "2.5", "--length must be comma-separated integers >= 1, e.g. 1,2,4,8; got '2.5'"),
    ("--learner-beta", "x0.5,fast", "learner_beta must be positive numbers"),
    ("--learner-beta", "x-1", "got 'x-1'"),
])
def test_experiment_bad_list_is_a_one_line_error(tmp_path, capsys, option, value, message):
    assert main(["experiment", "sorting", option, value, "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert message in err
    assert err.count("\n") == 1


def test_bad_number_list_is_rejected_by_the_parser(capsys):
    with pytest.raises(SystemExit):
        main(["experiment", "forestworld", "--noise", "a,b"])
    assert "comma-separated numbers" in capsys.readouterr().err


# --- --backend: the forward-backward kernels of learn and experiment -------------------------


def test_experiment_backend_reaches_the_learners_and_agrees_with_numpy(tmp_path, built):
    pytest.importorskip("numba")
    runs = {}
    for backend in ("numpy", "numba"):
        built.clear()
        out = tmp_path / backend
        assert main(["experiment", "sorting", "--occlusion", "0.2", "--noise", "0.3",
                     "--batches", "1", "--trajectories", "2", "--length", "8", "--methods",
                     "mmap-birl,hidden-data-em,maxent", "--workers", "1", "--backend", backend,
                     "--out", str(out)]) == 0
        assert [getattr(e, "backend", None) for e in built] == [backend, None, None]
        rows = list(csv.DictReader((out / "results.csv").open()))
        assert [r["backend"] for r in rows] == [backend] * 3
        summary = json.loads((out / "summary.json").read_text())
        assert summary["config"]["backend"] == backend
        assert summary["trial_backends"] == {backend: 3}
        runs[backend] = rows, [e.theta_ for e in built]
    (ref, ref_theta), (fast, fast_theta) = runs["numpy"], runs["numba"]
    for a, b, ta, tb in zip(ref, fast, ref_theta, fast_theta, strict=True):
        np.testing.assert_allclose(tb, ta, rtol=0, atol=1e-9, err_msg=a["method"])
        assert float(b["ile"]) == pytest.approx(float(a["ile"]), rel=1e-9, abs=1e-9)
        assert (a["method"], a["n_iter"], a["exact_policy"]) == \
            (b["method"], b["n_iter"], b["exact_policy"])


@pytest.mark.parametrize("method", ["mmap-birl", "hidden-data-em", "maxent"])
def test_learn_backend_reaches_the_learner_and_agrees_with_numpy(tmp_path, built, method,
                                                                  perceived_sessions):
    from onionsort.stages.models import CALIBRATION_FILE, DEFAULT_MODELS

    pytest.importorskip("numba")
    models = {}
    for backend in ("numpy", "numba"):
        out = tmp_path / backend
        assert main(["learn", *map(str, perceived_sessions), "--method", method,
                     "--observation-model", str(DEFAULT_MODELS / CALIBRATION_FILE),
                     "--allow-model-mismatch", "--backend", backend, "--out", str(out)]) == 0
        est = built[-1]
        assert getattr(est, "backend", None) == (backend if method == "mmap-birl" else None)
        model = json.loads((out / "model.json").read_text())
        assert model["backend"] == backend and model["method"] == method
        models[backend] = est.theta_, model
    (ref, ref_model), (fast, fast_model) = models["numpy"], models["numba"]
    np.testing.assert_allclose(fast, ref, rtol=0, atol=1e-9)
    assert fast_model["policy_indices"] == ref_model["policy_indices"]
    assert fast_model["n_iter"] == ref_model["n_iter"]


def test_learn_assumes_the_beta_and_prior_it_is_given(tmp_path, built, perceived_sessions):
    """``--beta`` and ``--prior-std`` reach the learner and model.json; their defaults are the
    simulated sorter's (the domain's own)."""
    from irl.domains.onion_sorting import onion_sorting
    from onionsort.configs.learn import LearnConfig
    from onionsort.stages.models import CALIBRATION_FILE, DEFAULT_MODELS

    fields = LearnConfig.__dataclass_fields__
    assert fields["beta"].default == onion_sorting().beta
    assert fields["prior_std"].default == onion_sorting().prior.std
    argv = ["learn", *map(str, perceived_sessions), "--observation-model",
            str(DEFAULT_MODELS / CALIBRATION_FILE), "--allow-model-mismatch"]
    assert main([*argv, "--out", str(tmp_path / "default")]) == 0
    assert main([*argv, "--beta", "0.2", "--prior-std", "0.5", "--out", str(tmp_path / "b")]) == 0
    default, assumed = built[-2], built[-1]
    assert (default.beta, assumed.beta) == (1.5, 0.2)
    assert float(np.ravel(assumed.prior.std)[0]) == 0.5
    model = json.loads((tmp_path / "b" / "model.json").read_text())
    assert (model["beta"], model["prior_std"]) == (0.2, 0.5)
    # a tighter prior and a less rational demonstrator pull the weights toward 0
    assert np.linalg.norm(assumed.theta_) < np.linalg.norm(default.theta_)


@pytest.mark.parametrize("posterior_method", ["laplace", "mcmc"])
def test_learn_posterior_writes_samples_confidence_plot_and_rerun(tmp_path, perceived_sessions,
                                                                  posterior_method, capsys):
    from rerun.chunk import RrdReader

    from irl.posterior import load_posterior
    from onionsort.stages.learn import load_confidence
    from onionsort.stages.models import CALIBRATION_FILE, DEFAULT_MODELS

    out = tmp_path / "run"
    assert main(["learn", *map(str, perceived_sessions), "--posterior", "--samples", "200",
                 "--posterior-method", posterior_method, "--observation-model",
                 str(DEFAULT_MODELS / CALIBRATION_FILE), "--allow-model-mismatch",
                 "--out", str(out)]) == 0
    assert "P(the policy is optimal)" in capsys.readouterr().out
    model = json.loads((out / "model.json").read_text())
    doc = json.loads((out / "policy_confidence.json").read_text())
    post = load_posterior(out / "posterior.npz")
    assert post.theta.shape == (200, 6) and post.method == posterior_method
    assert model["posterior"]["risk"] == doc["risk"]
    assert len(doc["states"]) == 48
    for s, row in enumerate(doc["states"]):
        assert sum(row["confidence"].values()) == pytest.approx(1.0, abs=1e-3)
        assert row["map_action"] == model["policy"][s]["action"]
        assert row["map_action"] in row["credible_90"]
    np.testing.assert_allclose(load_confidence(out), post.map_confidence(), atol=1e-4)
    assert (out / "policy_confidence.png").stat().st_size > 10_000
    paths = {c.entity_path for c in RrdReader(out / "learn.rrd").store().stream()}
    assert {"/learn/confidence", "/learn/least_sure"} <= paths
    # suggest: the states ranked by the expected regret of the learned action
    from irl.domains import onion_sorting
    from irl.posterior import expected_regret

    assert main(["suggest", str(out), "--top", "3", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    mdp = onion_sorting().mdp
    regret = np.where(mdp.reachable_states(), expected_regret(post, mdp), 0.0)
    assert [r["state"] for r in rows] == \
        [int(s) for s in regret.argsort(kind="stable")[::-1][:len(rows)]]
    assert all(r["expected_regret"] > 0 and r["confidence"] < 1 for r in rows)
    assert rows and rows[0]["description"].startswith(("a ", "an "))
    assert main(["suggest", str(out)]) == 0
    assert "where another demonstration would help most" in capsys.readouterr().out


def test_learn_with_session_swaps_weighs_how_each_session_was_read(tmp_path, perceived_sessions,
                                                                   capsys):
    import dataclasses

    from onionsort.stages.models import CALIBRATION_FILE, DEFAULT_MODELS
    from state_abstraction.calibration import load_calibration

    shipped = load_calibration(DEFAULT_MODELS / CALIBRATION_FILE)
    calibration = dataclasses.replace(shipped, session_swaps={
        "sessions": 20, "swapped": 2, "prediction_counts": [[60, 5, 3], [6, 55, 3],
                                                            [0, 1, 90]]}).save(
        tmp_path / "calibration.json", extra={"models": shipped.models})
    out = tmp_path / "run"
    assert main(["learn", *map(str, perceived_sessions), "--method", "mmap-birl,map-birl",
                 "--session-swaps", "--posterior", "--posterior-method", "laplace",
                 "--samples", "100", "--observation-model", str(calibration),
                 "--allow-model-mismatch", "--out", str(out)]) == 0
    assert "posterior probability" in capsys.readouterr().out
    mmap = json.loads((out / "mmap-birl" / "model.json").read_text())
    assert mmap["session_swaps"]["rate"] == pytest.approx(3 / 22)
    p = mmap["session_swaps"]["p_swapped"]
    assert len(p) == len(perceived_sessions) and all(0.0 <= v <= 1.0 for v in p)
    readings = json.loads((out / "mmap-birl" / "policy_confidence.json").read_text())["readings"]
    assert sum(r["weight"] for r in readings) == pytest.approx(1.0, abs=1e-5)
    assert sum(r["n_samples"] for r in readings) == 100
    # MAP-BIRL reads observations at face value: no swaps for it
    face = out / "map-birl"
    assert "session_swaps" not in json.loads((face / "model.json").read_text())
    assert "readings" not in json.loads((face / "policy_confidence.json").read_text())


def test_learn_method_bc_clones_the_policy_without_a_reward(tmp_path, perceived_sessions,
                                                            capsys):
    """``learn --method bc,bc-em``: model.json has no weights but each action's probability;
    the report and the Rerun recording say so; the policy is what the estimator learned."""
    from rerun.chunk import RrdReader

    import irl
    from onionsort.stages.models import CALIBRATION_FILE, DEFAULT_MODELS
    from recordings import open_session
    from state_abstraction.calibration import load_calibration

    out = tmp_path / "run"
    cal = DEFAULT_MODELS / CALIBRATION_FILE
    assert main(["learn", *map(str, perceived_sessions), "--method", "bc,bc-em",
                 "--observation-model", str(cal), "--allow-model-mismatch", "--seed", "3",
                 "--out", str(out)]) == 0
    assert capsys.readouterr().out.count("no reward (behaviour cloning)") == 2
    demos = [open_session(p).perceived_demonstration() for p in perceived_sessions]
    dom = irl.domains.onion_sorting()
    om = load_calibration(cal, task=dom.task).observation_model()
    for method, variant in (("bc", "face-value"), ("bc-em", "em")):
        model = json.loads((out / method / "model.json").read_text())
        est = irl.BehaviorCloning(dom.mdp, om, variant=variant, seed=3).fit(demos)
        assert model["theta"] is None and model["method"] == method
        assert model["policy_indices"] == est.policy_.tolist()
        assert [r["probability"] for r in model["policy"]] == pytest.approx(
            est.action_probabilities_[np.arange(48), est.policy_], abs=1e-4)
        assert len(model["unseen_states"]) == len(est.unseen_states_)
        assert main(["report", str(out / method)]) == 0
        report = (out / method / "report.md").read_text()
        assert "learns no reward" in report and "probability" in report
        assert (out / method / "learning_curve.png").is_file()
        paths = {c.entity_path for c in RrdReader(out / method / "learn.rrd").store().stream()}
        assert {"/learn/theta", "/learn/policy"} <= paths
    assert len(json.loads((out / "bc-em" / "learning_curve.json").read_text())) >= 2


def test_experiment_runs_behaviour_cloning_beside_the_reward_learners(tmp_path):
    out = tmp_path / "run"
    assert main(["experiment", "sorting", "--occlusion", "0.2", "--noise", "0.3", "--batches",
                 "2", "--trajectories", "1,4", "--methods", "mmap-birl,bc,bc-em", "--workers",
                 "1", "--out", str(out)]) == 0
    rows = list(csv.DictReader((out / "results.csv").open()))
    assert {r["method"] for r in rows} == {"mmap-birl", "bc", "bc-em"} and len(rows) == 12
    # cloning acts at random where no demonstration went: it loses value in every batch,
    # more than the reward learner on average
    ile = {m: [float(r["normalized_ile"]) for r in rows if r["method"] == m]
           for m in ("mmap-birl", "bc", "bc-em")}
    assert min(ile["bc"] + ile["bc-em"]) > 0
    assert np.mean(ile["mmap-birl"]) < min(np.mean(ile["bc"]), np.mean(ile["bc-em"]))
    assert "bc-em" in (out / "report.md").read_text()


def test_the_parsers_repeated_choices_are_the_libraries():
    from irl.experiments import METHODS
    from irl.inference import BACKENDS
    from onionsort.configs import common as _args
    from onionsort.stages.export import EXPORT_FORMATS, ROS2_STORAGES
    from onionsort.stages.label import IMPORT_FORMATS, LABEL_FORMATS
    from onionsort.stages.label_select import SELECT_FORMATS

    assert (_args.BACKENDS, _args.METHODS) == (BACKENDS, METHODS)
    assert (_args.EXPORT_FORMATS, _args.ROS2_STORAGES) == (EXPORT_FORMATS, ROS2_STORAGES)
    assert (_args.LABEL_FORMATS, _args.SELECT_FORMATS) == (LABEL_FORMATS, SELECT_FORMATS)
    assert _args.IMPORT_FORMATS == IMPORT_FORMATS


def test_the_parsers_default_learners_are_the_stages():
    """``demo --methods`` and ``experiment --methods`` repeat their stages' defaults (the
    parser may not import the stages): the two must not drift apart."""
    from irl.experiments import REWARD_METHODS
    from onionsort.cli import build_parser
    from onionsort.configs import common as _args
    from onionsort.stages.demo import METHODS as DEMO_METHODS
    from onionsort.stages.experiment import ExperimentConfig

    parser = build_parser()
    demo = parser.parse_args(["demo"])
    experiment = parser.parse_args(["experiment", "sorting"])
    assert demo.methods == DEMO_METHODS
    assert tuple(experiment.methods.split(",")) == ExperimentConfig(domain="sorting").methods \
        == REWARD_METHODS == _args.IRL_METHODS


def test_building_the_parser_loads_neither_irl_torch_nor_the_stages():
    """Every command builds the whole parser when it starts: its choices must not import the
    learners (and scipy), torch or every stage (that took 1.6 of a command's 2.1 s start)."""
    import subprocess
    import sys

    code = ("import sys; from onionsort.cli import build_parser; build_parser(); "
            "print(sorted(m for m in ('irl', 'torch', 'scipy', 'onionsort.stages') "
            "if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)
    assert done.stdout.strip() == "[]"


def test_the_demos_and_evaluations_configs_load_no_torch():
    """A demo on workers never needs torch in the command (its workers load the models): its
    config, and the evaluation config it checks, must not load it (importing the fusion rules
    through ``perception`` took 4 of the demo's first 5 s)."""
    import subprocess
    import sys

    code = ("import sys; from pathlib import Path; "
            "from onionsort.stages import DemoConfig, EvaluateConfig; "
            "DemoConfig(out=Path('x'), fusion='noisy-or', defer_below=0.9); "
            "EvaluateConfig(run=Path('x'), fusion='log-odds'); import perception.fusion; "
            "print('torch' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)
    assert done.stdout.strip() == "False"
