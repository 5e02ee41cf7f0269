"""``onionsort experiment --resume``: an interrupted sweep, resumed, equals an uninterrupted one.

Each test interrupts a real run (a killed subprocess, or a trial that raises
``KeyboardInterrupt`` part-way), resumes it, and compares ``results.csv`` with an uninterrupted
run of the same sweep, every column but the timings.
"""

from __future__ import annotations

import csv
import json
import subprocess
import sys
import time

import pytest

import irl.experiments
from onionsort.cli import main

#: 4 quick points x 4 methods x 1 batch = 16 trials of a few hundredths of a second each.
SWEEP = ["experiment", "forestworld", "--quick", "--batches", "1", "--trajectories", "3",
         "--workers", "1"]
N_TRIALS = 16


def rows(path):
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def untimed(table):
    return [{k: v for k, v in r.items() if k != "seconds"} for r in table]


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    out = tmp_path_factory.mktemp("uninterrupted")
    assert main([*SWEEP, "--out", str(out)]) == 0
    table = rows(out / "results.csv")
    assert len(table) == N_TRIALS
    return table


def interrupt_after(monkeypatch, n_trials: int) -> None:
    """Make the sweep stop with ``KeyboardInterrupt`` when its ``n_trials + 1``-th trial starts."""
    real, calls = irl.experiments.run_trial, []

    def run_trial(trial):
        calls.append(trial)
        if len(calls) > n_trials:
            raise KeyboardInterrupt
        return real(trial)

    monkeypatch.setattr(irl.experiments, "run_trial", run_trial)


def interrupted_run(tmp_path, monkeypatch, n_trials: int = 5):
    out = tmp_path / "run"
    with monkeypatch.context() as m:
        interrupt_after(m, n_trials)
        assert main([*SWEEP, "--out", str(out)]) == 130  # the CLI's exit code for Ctrl-C
    partial = out / "results.csv.partial"
    assert len(rows(partial)) == n_trials
    assert not (out / "results.csv").exists()
    return out, partial


def test_a_killed_sweep_resumed_equals_an_uninterrupted_one(tmp_path, uninterrupted):
    out = tmp_path / "killed"
    partial = out / "results.csv.partial"
    proc = subprocess.Popen([sys.executable, "-m", "onionsort.cli", *SWEEP, "--out", str(out)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            if partial.exists() and len(rows(partial)) >= 3:
                break
            time.sleep(0.01)
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode < 0, "the sweep ended before it could be interrupted"
    kept = rows(partial)
    assert 3 <= len(kept) < N_TRIALS
    assert not (out / "results.csv").exists()

    assert main([*SWEEP, "--out", str(out), "--resume"]) == 0
    resumed = rows(out / "results.csv")
    assert untimed(resumed) == untimed(uninterrupted)
    # the kept trials were not run again: their timings are those of the killed run
    by_trial = {tuple(r[k] for k in ("method", "occlusion", "noise", "batch")): r["seconds"]
                for r in resumed}
    for r in kept:
        assert by_trial[r["method"], r["occlusion"], r["noise"], r["batch"]] == r["seconds"]
    assert not partial.exists()
    assert not (out / "results.csv.partial.json").exists()


def test_a_row_cut_short_by_the_interruption_is_run_again(tmp_path, monkeypatch, uninterrupted):
    out, partial = interrupted_run(tmp_path, monkeypatch, n_trials=5)
    text = partial.read_text()
    partial.write_text(text[: len(text) - 40])  # the last row, half written
    assert main([*SWEEP, "--out", str(out), "--resume"]) == 0
    assert untimed(rows(out / "results.csv")) == untimed(uninterrupted)


def test_resume_runs_only_the_missing_trials(tmp_path, monkeypatch, uninterrupted):
    out, _ = interrupted_run(tmp_path, monkeypatch, n_trials=6)
    real, ran = irl.experiments.run_trial, []

    def counting(trial):
        ran.append(trial)
        return real(trial)

    monkeypatch.setattr(irl.experiments, "run_trial", counting)
    assert main([*SWEEP, "--out", str(out), "--resume"]) == 0
    assert len(ran) == N_TRIALS - 6
    assert untimed(rows(out / "results.csv")) == untimed(uninterrupted)


def test_a_partial_run_is_not_overwritten_without_resume(tmp_path, monkeypatch, capsys):
    out, partial = interrupted_run(tmp_path, monkeypatch)
    before = partial.read_bytes()
    capsys.readouterr()
    assert main([*SWEEP, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--resume" in err and "interrupted sweep" in err
    assert err.count("\n") == 1
    assert partial.read_bytes() == before


@pytest.mark.parametrize("change, message", [
    (["--seed", "1"], "seed 0 there, 1 here"),
    (["--batches", "2"], "batches 1 there, 2 here"),
    (["--methods", "mmap-birl"], "methods ["),
])
def test_resume_refuses_a_sweep_with_other_parameters(tmp_path, monkeypatch, capsys, change,
                                                      message):
    out, partial = interrupted_run(tmp_path, monkeypatch)
    before = partial.read_bytes()
    capsys.readouterr()
    assert main([*SWEEP, *change, "--out", str(out), "--resume"]) == 2
    err = capsys.readouterr().err
    assert "cannot resume" in err and message in err
    assert err.count("\n") == 1
    assert partial.read_bytes() == before
    assert not (out / "results.csv").exists()


def test_a_sweep_resumed_with_the_other_backend_equals_an_uninterrupted_one(tmp_path,
                                                                          monkeypatch,
                                                                          uninterrupted):
    """The backend is how trials are computed, not what: a numpy sweep may be finished with
    numba. Each row names the backend that computed it, the summary counts them, and the
    scores equal the uninterrupted numpy run's to 1e-9."""
    pytest.importorskip("numba")
    out, _ = interrupted_run(tmp_path, monkeypatch, n_trials=5)
    assert main([*SWEEP, "--out", str(out), "--resume", "--backend", "numba"]) == 0
    resumed = rows(out / "results.csv")
    assert [r["backend"] for r in resumed] == ["numpy"] * 5 + ["numba"] * (N_TRIALS - 5)
    scores = ("ile", "normalized_ile")
    for mine, ref in zip(resumed, uninterrupted, strict=True):
        assert {k: v for k, v in mine.items() if k not in ("seconds", "backend", *scores)} == \
            {k: v for k, v in ref.items() if k not in ("seconds", "backend", *scores)}
        for k in scores:
            assert float(mine[k]) == pytest.approx(float(ref[k]), rel=1e-9, abs=1e-9)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["config"]["backend"] == "numba"
    assert summary["trial_backends"] == {"numba": N_TRIALS - 5, "numpy": 5}
    assert summary["resumed_trials"] == 5
