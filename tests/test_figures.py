"""docs/make_figures.py: the README's figures from a tiny run, the record of their commands, and
the pieces (finding or refusing a run, the efficiency figure's numbers)."""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "docs" / "make_figures.py"
METHODS = ("mmap-birl", "map-birl", "hidden-data-em", "maxent")


@pytest.fixture(scope="module")
def figures():
    """The script as a module."""
    spec = importlib.util.spec_from_file_location("make_figures", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up there
    try:
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.modules.pop(spec.name, None)


def _point(method, noise, n, nile, exact, batches=2):
    return {"method": method, "occlusion": 0.2, "noise": noise, "trajectories": n,
            "length": 20, "learner": "x1", "learner_beta": 1.5, "batches": batches,
            "normalized_ile_mean": nile, "normalized_ile_ci_low": max(0.0, nile - 5),
            "normalized_ile_ci_high": nile + 5, "exact_policy_rate": exact,
            "exact_policy_ci_low": max(0.0, exact - 0.2),
            "exact_policy_ci_high": min(1.0, exact + 0.2)}


def _summary(spec, points):
    return {"config": dict(spec.expect), "points": points}


def _points():
    return [_point(m, noise, n, 10.0 * k + n + 100 * noise, 1.0 - 0.1 * k)
            for noise in (0.3, 0.45) for n in (1, 2) for k, m in enumerate(METHODS)]


def figures_methods():
    """The efficiency figure's learners: the four reward learners, then behaviour cloning."""
    return (*METHODS, "bc", "bc-em")


def test_quick_run_makes_every_figure_and_records_its_commands(tmp_path):
    runs, out = tmp_path / "runs", tmp_path / "figures"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
    done = subprocess.run([sys.executable, str(SCRIPT), "--quick", "--runs", str(runs),
                           "--out", str(out)], capture_output=True, text=True, cwd=tmp_path,
                          env=env, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    from PIL import Image

    # (min width, max width, min height, max height) in pixels
    expected = {"pipeline.png": (900, 1100, 500, 620), "efficiency.png": (800, 1000, 560, 680),
                "workcell.png": (450, 550, 380, 460)}
    for name, (w_lo, w_hi, h_lo, h_hi) in expected.items():
        path = out / name
        with Image.open(path) as image:
            image.verify()  # a complete, valid PNG
        with Image.open(path) as image:
            assert image.format == "PNG"
            assert w_lo <= image.width <= w_hi and h_lo <= image.height <= h_hi, image.size
            assert len(image.convert("RGB").getcolors(1 << 16) or ()) > 8  # not blank
        assert path.stat().st_size < 300 * 1024
    assert sorted(p.name for p in out.iterdir()) == ["FIGURES.md", *sorted(expected)]
    record = (out / "FIGURES.md").read_text()
    command = ("onionsort experiment sorting --trajectories 1,2 --noise 0.3,0.45 --occlusion 0.2 "
               "--batches 2 --workers 1 --methods mmap-birl,map-birl,hidden-data-em,maxent,bc,"
               f"bc-em --out {runs / 'efficiency-quick'}")
    assert command in record
    assert "--quick" in record and "session seed 0" in record and "station seed 5" in record
    for name in expected:
        assert f"## {name}" in record
    summary = json.loads((runs / "efficiency-quick" / "summary.json").read_text())
    assert summary["config"]["trajectories"] == [1, 2]
    assert summary["config"]["methods"] == list(figures_methods())
    # the record's table holds the run's means
    row = next(p for p in summary["points"] if p["method"] == "mmap-birl"
               and p["noise"] == 0.3 and p["trajectories"] == 2)
    assert (f"| 30% | 2 | {row['normalized_ile_mean']:.1f} · {row['exact_policy_rate']:.2f}"
            in record)


def test_no_run_names_the_command_in_one_line(figures, tmp_path, capsys):
    code = figures.main(["--no-run", "--runs", str(tmp_path / "runs"),
                         "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1
    assert figures.EFFICIENCY.command(tmp_path / "runs") in err
    assert "--trajectories 1,2,4,8 --noise 0.3,0.45 --occlusion 0.2 --batches 20" in err
    assert not (tmp_path / "runs").exists()


def test_an_existing_run_is_read_not_rerun(figures, tmp_path, monkeypatch):
    spec = figures.EFFICIENCY
    folder = spec.folder(tmp_path)
    folder.mkdir()
    (folder / "summary.json").write_text(json.dumps(_summary(spec, _points())))

    def refuse(*args, **kwargs):
        raise AssertionError("the run exists; nothing should be run")
    monkeypatch.setattr(figures.subprocess, "run", refuse)
    assert figures.ensure_run(spec, tmp_path)["points"] == _points()


def test_a_run_of_another_sweep_is_refused(figures, tmp_path):
    spec = figures.EFFICIENCY
    folder = spec.folder(tmp_path)
    folder.mkdir()
    other = _summary(spec, _points())
    other["config"]["batches"] = 5
    (folder / "summary.json").write_text(json.dumps(other))
    with pytest.raises(figures.FigureError, match=r"another sweep \(batches=5\).*--batches 20"):
        figures.ensure_run(spec, tmp_path, allow_run=False)


def test_a_missing_run_is_made_and_an_interrupted_one_resumed(figures, tmp_path, monkeypatch):
    spec = figures.EFFICIENCY_QUICK
    calls = []

    def fake_run(argv, check):
        calls.append(argv)
        folder = spec.folder(tmp_path)
        folder.mkdir(exist_ok=True)
        (folder / "summary.json").write_text(json.dumps(_summary(spec, _points())))
        return subprocess.CompletedProcess(argv, 0)
    monkeypatch.setattr(figures.subprocess, "run", fake_run)
    figures.ensure_run(spec, tmp_path)
    assert calls == [[sys.executable, "-m", "onionsort.cli", *spec.argv(tmp_path)]]

    (spec.folder(tmp_path) / "summary.json").unlink()
    (spec.folder(tmp_path) / "results.csv.partial").write_text("")
    figures.ensure_run(spec, tmp_path)
    assert calls[-1][-1] == "--resume"


def test_a_failing_command_is_one_clear_error(figures, tmp_path, monkeypatch):
    monkeypatch.setattr(figures.subprocess, "run",
                        lambda *a, **k: subprocess.CompletedProcess(a, 2))
    with pytest.raises(figures.FigureError, match="failed \\(exit code 2\\)"):
        figures.ensure_run(figures.EFFICIENCY_QUICK, tmp_path)


def test_efficiency_figure_and_table(figures, tmp_path):
    points = _points()
    fig = figures.efficiency_figure(points)
    axes = fig.get_axes()
    assert len(axes) == 4  # (ILE, exact-policy rate) x (noise 30%, 45%)
    assert [ax.get_title() for ax in axes[:2]] == ["observation noise 30%",
                                                   "observation noise 45%"]
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert labels == [figures.METHOD_LABELS[m] for m in METHODS]
    # each method's line goes through its means (dodged in x, not in y)
    line = axes[0].get_lines()[0]
    assert list(line.get_ydata()) == [p["normalized_ile_mean"] for p in points
                                      if p["method"] == "mmap-birl" and p["noise"] == 0.3]
    path = figures.save_png(fig, tmp_path / "efficiency.png", colors=64)
    assert path.exists() and not list(tmp_path.glob("*.partial"))
    table = figures.efficiency_table(points)
    assert table[0] == "| noise | demos | " + " | ".join(METHODS) + " |"
    assert table[2] == "| 30% | 1 | 31.0 · 1.00 | 41.0 · 0.90 | 51.0 · 0.80 | 61.0 · 0.70 |"
    assert len(table) == 2 + 4


def test_efficiency_figure_refuses_mixed_settings(figures):
    points = _points()
    points[0] = {**points[0], "occlusion": 0.1}
    with pytest.raises(figures.FigureError, match="one occlusion"):
        figures.efficiency_figure(points)


def test_pipeline_names_the_real_commands(figures):
    from onionsort.cli import build_parser

    commands = {name for action in build_parser()._actions
                if isinstance(action, argparse._SubParsersAction) for name in action.choices}
    stages = {title for _, _, _, title, _, kind in figures.PIPELINE_BOXES.values()
              if kind != "sim" or title == "evaluate"} - {"reward & policy", "Rerun logging"}
    assert stages <= commands, stages - commands
    assert {"record", "perceive", "calibrate", "learn", "evaluate", "import"} <= stages
    for src, dst, *_ in figures.PIPELINE_ARROWS:
        assert src in figures.PIPELINE_BOXES and dst in figures.PIPELINE_BOXES
