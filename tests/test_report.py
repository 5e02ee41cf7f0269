"""``onionsort report``: one Markdown page of a run folder's settings and results.

The demo's report is checked on the session's ``onionsort demo --quick`` folder (the acceptance
test); the other kinds on folders built in seconds: a quick sweep, a learning run on simulated
observations, a demo's method folder, an evaluation, and a demo with repeats and deferral
assembled from its files' format.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest

from onionsort.cli import main
from onionsort.stages.report import PR_FIGURE, REPORT_FILE, ReportConfig, report, run_kind
from tests.test_demo import SHIPPED

IMAGE = re.compile(r"!\[[^\]]*\]\(([^)\s]+)\)")
PNG = b"\x89PNG\r\n\x1a\n"


def _images(folder: Path) -> list[str]:
    """The image links of ``folder/report.md``; each must be a PNG file under ``folder``."""
    text = (folder / REPORT_FILE).read_text()
    links = IMAGE.findall(text)
    for link in links:
        assert not Path(link).is_absolute() and ".." not in Path(link).parts, link
        assert (folder / link).read_bytes()[:8] == PNG, f"{link} is linked but is no PNG file"
    return links


def _section(text: str, title: str) -> str:
    """The text of the ``## title`` section of a report."""
    start = text.index(f"## {title}")
    end = text.find("\n## ", start + 1)
    return text[start:] if end < 0 else text[start:end]


def _recordings_listed(folder: Path, text: str) -> None:
    """Every .rrd and .mcap of the run is listed with the command that opens it, and nothing
    else is."""
    files = sorted(p.relative_to(folder).as_posix()
                   for p in [*folder.rglob("*.rrd"), *folder.rglob("*.mcap")])
    listed = re.findall(r"^\| `([^`]+)` \| (?:Rerun recording|MCAP session) \|", text, re.M)
    assert sorted(listed) == files
    for rel in files:
        assert f"`rerun {rel}`" in text


def _cells(row: dict) -> str:
    return " | ".join(str(row[c]) for c in ("tp", "fp", "tn", "fn"))


# --- demo: the acceptance test ------------------------------------------------------------


@SHIPPED
def test_quick_demo_report_holds_table_1_calibration_plots_and_recordings(quick_demo, capsys):
    out, printed = quick_demo
    # the demo wrote its report at the end, and said where
    assert f"report: {out / REPORT_FILE}" in printed
    written = (out / REPORT_FILE).read_text()
    # the report is derived: written again from the files, it is the same page
    (out / REPORT_FILE).unlink()
    (out / PR_FIGURE).unlink()
    assert main(["report", str(out)]) == 0
    assert f"wrote {out / REPORT_FILE} (demo run)" in capsys.readouterr().out
    text = (out / REPORT_FILE).read_text()
    assert text == written
    assert not list(out.rglob("*.partial"))

    links = _images(out)
    assert len(links) >= 2
    assert {PR_FIGURE, "calibration/confusion.png", "mmap-birl/learning_curve.png",
            "hidden-data-em/learning_curve.png"} <= set(links)

    results = json.loads((out / "results.json").read_text())
    table_1 = _section(text, "Table 1")
    for method, pooled in results["methods"].items():
        row = (f"| {method} | ours (simulation, 1 repeat(s)) | {_cells(pooled)} | "
               f"{pooled['precision']:.3f} [{pooled['precision_ci'][0]:.2f}, "
               f"{pooled['precision_ci'][1]:.2f}] | {pooled['recall']:.3f} "
               f"[{pooled['recall_ci'][0]:.2f}, {pooled['recall_ci'][1]:.2f}]")
        assert row in table_1
    assert "| mmap-birl | paper (physical robot) | 23 | 2 | 18 | 7 |" in table_1
    assert "Per repeat" not in text and "## Deferring" not in text  # one repeat, no deferral
    calibration = _section(text, "Calibration")
    assert f"| {results['state_error_rate']:.3f} |" in calibration
    assert f"| {results['pair_error_rate']:.3f} |" in calibration
    backwards = results["sessions_read_backwards"]
    assert (f"Held-out sessions: {backwards['swapped']} of {backwards['sessions']} sessions "
            "read backwards") in calibration
    assert f"held-out sessions: {backwards['swapped']} of" in printed
    settings = _section(text, "Settings")
    assert "| line-up | 10 onions, 6 blemished |" in settings
    assert "| size | quick |" in settings
    _recordings_listed(out, text)
    assert "`rerun sessions.rrd`" in text and "`rerun mmap-birl/evaluation.mcap`" in text


@SHIPPED
def test_a_demo_method_folder_reports_as_learn_with_its_evaluation(quick_demo, tmp_path):
    demo, _ = quick_demo
    run = tmp_path / "mmap-birl"
    shutil.copytree(demo / "mmap-birl", run)
    (tmp_path / "results.json").write_bytes((demo / "results.json").read_bytes())
    assert run_kind(run) == "learn"
    text = report(ReportConfig(run=run)).read_text()
    model = json.loads((run / "model.json").read_text())
    evaluation = json.loads((run / "evaluation.json").read_text())
    repeat = json.loads((demo / "results.json").read_text())["methods"]["mmap-birl"]
    for feature, weight in model["theta"].items():
        assert f"| {feature} | {weight:.4f} |" in text
    # the demo this run belongs to recorded its ILE; the report quotes it
    assert f"against the sorter's true reward: {repeat['per_repeat'][0]['ile']:.4f}" in text
    for p in model["policy"]:
        assert f"| {p['state']} | {p['action']} |" in text
    sort = _section(text, "Evaluation")
    assert (f"| {evaluation['n_onions']} | {_cells(evaluation)} | "
            f"{evaluation['precision']:.3f} | {evaluation['recall']:.3f} |") in sort
    assert set(_images(run)) == {"learning_curve.png", PR_FIGURE}
    _recordings_listed(run, text)

    # the evaluation alone (its files copied into a folder of their own) is an evaluate run
    alone = tmp_path / "eyes"
    alone.mkdir()
    for name in ("evaluation.json", "evaluation.rrd", "evaluation.mcap"):
        shutil.copy(run / name, alone / name)
    assert run_kind(alone) == "evaluate"
    text = report(ReportConfig(run=alone)).read_text()
    assert f"| {_cells(evaluation)} |" in text
    assert _images(alone) == [PR_FIGURE]
    _recordings_listed(alone, text)


# --- a demo with repeats and deferral, from its files' format ------------------------------


def _repeat(seed: int, counts: tuple[int, ...], deferring: tuple[int, ...]) -> dict:
    """One repeat's result as the demo records it; ``deferring``: TP, FP, TN, FN of the
    deferring sort, and how many onions it deferred."""
    def scored(tp, fp, tn, fn) -> dict:
        return {"tp": tp, "fp": fp, "tn": tn, "fn": fn, "precision": tp / (tp + fp),
                "recall": tp / (tp + fn)}

    return {"seed": seed, **scored(*counts), "learn_seconds": 1.5, "backend": "numpy",
            "theta": {"good_on_conveyor": 1.0, "bad_in_bin": 2.0}, "ile": 0.5 * seed,
            "undecided": 0,
            "posterior": {"method": "laplace", "n_samples": 100,
                          "risk": {"p_map_optimal": 0.25 + 0.5 * seed, "expected_ile": 1.0}},
            "deferring": {**scored(*deferring[:4]), "deferred": deferring[4]}}


@pytest.fixture
def demo_with_repeats(tmp_path) -> Path:
    """A demo folder of 2 repeats with deferral: its results.json built as the demo builds
    it, a learning curve in one method folder only, no calibration folder, one recording."""
    from onionsort.plots import learning_curve_figure
    from onionsort.stages.demo import PAPER_TABLE_1, _pooled

    out = tmp_path / "demo"
    runs = {"mmap-birl": [_repeat(0, (5, 1, 3, 1), (5, 0, 3, 1, 1)),
                          _repeat(1, (4, 0, 4, 2), (4, 0, 4, 2, 0))],
            "map-birl": [_repeat(0, (3, 2, 2, 3), (3, 1, 2, 2, 2)),
                         _repeat(1, (6, 0, 4, 0), (6, 0, 4, 0, 0))],
            "hidden-data-em": [_repeat(0, (2, 2, 2, 4), (2, 2, 2, 4, 0)),
                               _repeat(1, (1, 1, 3, 5), (1, 1, 3, 5, 0))]}
    results = {"methods": {m: _pooled(r, 0) for m, r in runs.items()}, "paper": PAPER_TABLE_1,
               "quick": True, "seed": 0, "difficulty": "hard", "repeats": 2,
               "backends": ["numpy"], "sessions": 2, "onions": 10, "blemished": 6,
               "state_error_rate": 0.25, "pair_error_rate": 0.375,
               "inspection": {"views": 5, "threshold": 0.5, "fusion": "noisy-or"},
               "seconds": 12.0, "defer_below": 0.9,
               "deferring": {m: _pooled([r["deferring"] for r in runs[m]], 0)
                             for m in ("mmap-birl", "map-birl")}}
    out.mkdir()
    (out / "results.json").write_text(json.dumps(results))
    (out / "repeat_1" / "map-birl").mkdir(parents=True)
    learning_curve_figure([3.0, 2.0, 1.0], "map-birl",
                          out / "repeat_1" / "map-birl" / "learning_curve.png")
    (out / "repeat_0").mkdir()
    (out / "repeat_0" / "sessions.rrd").write_bytes(b"RRF2")
    return out


def test_demo_report_gives_each_repeat_the_deferring_sort_and_links_only_files_there(
        demo_with_repeats):
    out = demo_with_repeats
    results = json.loads((out / "results.json").read_text())
    text = report(ReportConfig(run=out)).read_text()
    # pooled rows as results.json has them, then each repeat's own
    assert "| mmap-birl | ours (simulation, 2 repeat(s)) | 9 | 1 | 7 | 3 |" in text
    assert "| mmap-birl | ours, deferring below 0.9 (1 deferred, rate 0.050) | 9 | 0 | 7 | 3 |" \
        in text
    per_repeat = _section(text, "Table 1")
    assert "| 0 | `repeat_0/` | 0 | mmap-birl | 5 | 1 | 3 | 1 | 0.833 | 0.833 | 0.000 | 0 |" \
        in per_repeat
    assert "| 1 | `repeat_1/` | 1 | hidden-data-em | 1 | 1 | 3 | 5 | 0.500 | 0.167 | 0.500 | 0 |" \
        in per_repeat
    deferring = _section(text, "Deferring")
    d = results["deferring"]["mmap-birl"]
    assert (f"| mmap-birl | 9 | 0 | 7 | 3 | 1 | {d['deferral_rate']:.3f} | "
            f"{d['precision']:.3f} [{d['precision_ci'][0]:.2f}, {d['precision_ci'][1]:.2f}]"
            ) in deferring
    assert "| 0.250, 0.750 |" in deferring  # P(the policy is optimal) of each repeat
    assert "hidden-data-em" not in deferring
    assert "| error rate | value |" in text and "| 0.375 |" in text
    # only what exists is linked: no calibration folder here, one learning curve
    assert set(_images(out)) == {PR_FIGURE, "repeat_1/map-birl/learning_curve.png"}
    assert "`rerun repeat_0/sessions.rrd`" in text


def test_a_failed_report_leaves_the_earlier_one(demo_with_repeats, capsys):
    out = demo_with_repeats
    before = report(ReportConfig(run=out)).read_text()
    (out / "calibration").mkdir()
    (out / "calibration" / "calibration.json").write_text("{broken")
    assert main(["report", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "calibration.json is not JSON" in err
    assert (out / REPORT_FILE).read_text() == before
    assert not list(out.rglob("*.partial"))


# --- experiment and learn ---------------------------------------------------------------


def test_experiment_writes_a_report_with_its_summary_and_plots(tmp_path, capsys):
    out = tmp_path / "sweep"
    assert main(["experiment", "forestworld", "--occlusion", "0.2", "--noise", "0.3",
                 "--batches", "2", "--trajectories", "2,3", "--methods", "mmap-birl,maxent",
                 "--workers", "1", "--out", str(out)]) == 0
    assert f"report: {out / REPORT_FILE}" in capsys.readouterr().out
    text = (out / REPORT_FILE).read_text()
    summary = json.loads((out / "summary.json").read_text())
    rows = _section(text, "Summary")
    for p in summary["points"]:
        assert (f"| {p['method']} | {p['learner']} ({p['learner_beta']:.3g}) | "
                f"{p['occlusion']:.2f} | {p['noise']:.2f} | {p['trajectories']} | "
                f"{p['length']} | 2 | {p['normalized_ile_mean']:.3f} "
                f"[{p['normalized_ile_ci_low']:.3f}, {p['normalized_ile_ci_high']:.3f}] | "
                f"{p['exact_policy_rate']:.3f} [{p['exact_policy_ci_low']:.2f}, "
                f"{p['exact_policy_ci_high']:.2f}] |") in rows
    assert len([line for line in rows.splitlines()
                if line.startswith(("| mmap-birl |", "| maxent |"))]) == len(summary["points"])
    links = _images(out)
    assert links[0] == "normalized_ile_vs_demonstrations.png"  # the data-efficiency curve
    assert set(links) == {p.name for p in out.glob("*.png")}  # every plot of the sweep
    assert "holds no Rerun (`.rrd`) or MCAP (`.mcap`) recordings" in text
    assert "| domain | forestworld |" in text


def test_learn_report_gives_reward_policy_curve_and_confidence(tmp_path, perceived_sessions,
                                                               capsys):
    from onionsort.stages.models import CALIBRATION_FILE, DEFAULT_MODELS

    run = tmp_path / "learn"
    assert main(["learn", *map(str, perceived_sessions), "--posterior", "--samples", "40",
                 "--posterior-method", "laplace", "--observation-model",
                 str(DEFAULT_MODELS / CALIBRATION_FILE), "--allow-model-mismatch",
                 "--out", str(run)]) == 0
    assert main(["report", str(run)]) == 0
    assert "(learn run)" in capsys.readouterr().out
    text = (run / REPORT_FILE).read_text()
    model = json.loads((run / "model.json").read_text())
    confidence = json.loads((run / "policy_confidence.json").read_text())
    assert "| method | mmap-birl |" in text and "| steps | 20 (" in text
    assert "Inverse learning error: not recorded" in text  # learned outside a demo
    for row in confidence["states"]:
        conf = row["confidence"][row["map_action"]]
        assert (f"| {row['state']} | {row['map_action']} | {conf:.2f} | "
                f"{', '.join(row['credible_90'])} |") in text
    unsure = sum(r["confidence"][r["map_action"]] < 0.9 for r in confidence["states"])
    section = _section(text, "Policy confidence")
    assert f"| {confidence['risk']['p_map_optimal']:.3f} |" in section
    assert (f"below 0.9 ({unsure})" in section) if unsure else ("at least 0.9" in section)
    assert set(_images(run)) == {"learning_curve.png", "policy_confidence.png"}
    assert not (run / PR_FIGURE).exists()  # not evaluated: no sorting scores to draw
    assert len(model["policy"]) == 48


# --- folders that are no run ------------------------------------------------------------


@pytest.mark.parametrize("make, words", [
    (lambda d: d / "nothing", ["nothing does not exist", "onionsort demo"]),
    (lambda d: _write(d / "afile", "x"), ["afile is a file, not a folder"]),
    (lambda d: _mkdir(d / "empty"), ["empty is no run folder (it is empty)",
                                     "results.json, summary.json, model.json or "
                                     "evaluation.json"]),
    (lambda d: _write(d / "other" / "notes.txt", "x").parent,
     ["other is no run folder (it holds notes.txt)", "onionsort experiment"]),
    (lambda d: _write(d / "half" / "progress" / "config.json", "{}").parents[1],
     ["half holds an unfinished demo", "onionsort demo --resume --out"]),
    (lambda d: _write(d / "cut" / "results.csv.partial", "method\n").parent,
     ["cut holds an interrupted sweep", "--resume"]),
    (lambda d: _write(d / "two" / "maxent" / "model.json", "{}").parents[1],
     ["two is no run folder itself but holds run folders (maxent)", "onionsort report",
      "two/maxent"]),
    (lambda d: _write(d / "bad" / "results.json", "{oops").parent,
     ["bad/results.json is not JSON"]),
    (lambda d: _write(d / "list" / "model.json", "[1, 2]").parent,
     ["list/model.json holds a JSON list"]),
])
def test_a_folder_that_is_no_run_is_one_line(tmp_path, capsys, make, words):
    folder = make(tmp_path)
    assert main(["report", str(folder)]) == 2
    err = capsys.readouterr().err
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("onionsort report: error: "), err
    for word in words:
        assert word in lines[0]
    assert not (Path(folder) / REPORT_FILE).exists()


def _write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def _mkdir(path: Path) -> Path:
    path.mkdir()
    return path
