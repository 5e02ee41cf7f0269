"""Sweeps on other executors: Ray tasks give the process pool's rows, timings aside.

The Ray tests join a local instance started with ``ray.init(num_cpus=2)`` (the ``ray`` fixture
of ``tests/conftest.py``), skipped where Ray (the ``ray`` extra) is not installed, except in CI.
"""

from __future__ import annotations

import csv
import json
import sys
from concurrent.futures import ThreadPoolExecutor

from irl.experiments import SweepConfig, run_sweep, run_trials
from onionsort.cli import main

QUICK = ["experiment", "forestworld", "--quick"]


def untimed_rows(path):
    with path.open(newline="") as fh:
        return [{k: v for k, v in r.items() if k != "seconds"} for r in csv.DictReader(fh)]


def untimed(result):
    return {k: v for k, v in vars(result).items() if k != "seconds"}


def test_any_executor_gives_the_serial_results_by_trial():
    config = SweepConfig("forestworld", points=((0.2, 0.3), (0.0, 0.3)),
                         methods=("mmap-birl", "maxent"), batches=2, trajectories=2, length=6)
    trials = config.trials()
    serial = list(run_sweep(config))
    with ThreadPoolExecutor(max_workers=2) as pool:
        by_index = dict(run_trials(trials, executor=pool))
        ordered = list(run_sweep(config, executor=pool))
    assert sorted(by_index) == list(range(len(trials)))
    for i, trial in enumerate(trials):
        assert (by_index[i].method, by_index[i].occlusion, by_index[i].batch) == (
            trial.method, trial.occlusion, trial.batch)
    assert [untimed(by_index[i]) for i in range(len(trials))] == [untimed(r) for r in serial]
    assert [untimed(r) for r in ordered] == [untimed(r) for r in serial]


def test_ray_and_process_pool_sweeps_give_equal_rows(tmp_path, ray):
    pool, tasks = tmp_path / "pool", tmp_path / "ray"
    assert main([*QUICK, "--workers", "2", "--out", str(pool)]) == 0
    assert main([*QUICK, "--executor", "ray", "--out", str(tasks)]) == 0
    expected = untimed_rows(pool / "results.csv")
    assert len(expected) == 4 * 3 * 4  # quick points x batches x methods
    assert untimed_rows(tasks / "results.csv") == expected
    summary = json.loads((tasks / "summary.json").read_text())
    assert summary["executor"] == "ray"
    assert ray.is_initialized()  # the sweep joined this instance and left it running


def test_ray_resumes_a_process_pool_sweep(tmp_path, monkeypatch, ray):
    from tests.irl.test_experiments_resume import SWEEP, interrupted_run

    assert main([*SWEEP, "--out", str(tmp_path / "whole")]) == 0
    out, _ = interrupted_run(tmp_path, monkeypatch, n_trials=4)
    assert main([*SWEEP, "--executor", "ray", "--out", str(out), "--resume"]) == 0
    assert untimed_rows(out / "results.csv") == untimed_rows(tmp_path / "whole" / "results.csv")


def test_without_ray_the_ray_executor_is_a_one_line_error(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` now fails
    out = tmp_path / "run"
    assert main([*QUICK, "--executor", "ray", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert 'pip install -e ".[ray]"' in err
    assert err.count("\n") == 1
    assert not (out / "results.csv.partial").exists()


def test_a_ray_address_needs_the_ray_executor(tmp_path, capsys):
    assert main([*QUICK, "--ray-address", "auto", "--out", str(tmp_path / "x")]) == 2
    assert "ray_address is for executor 'ray'" in capsys.readouterr().err
