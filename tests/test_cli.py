"""End-to-end smoke tests of the console script on tiny configurations."""

import csv
import json

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
