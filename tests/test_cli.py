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
    assert all(float(r["ile"]) >= 0 for r in rows)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["config"]["domain"] == "forestworld"
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


def test_bad_number_list_is_rejected_by_the_parser(capsys):
    with pytest.raises(SystemExit):
        main(["experiment", "forestworld", "--noise", "a,b"])
    assert "comma-separated numbers" in capsys.readouterr().err
