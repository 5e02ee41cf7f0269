"""``onionsort demo --quick``: the end-to-end smoke test of the whole pipeline."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader

from onionsort.cli import main
from onionsort.stages.models import CLASSIFIER_FILE, DEFAULT_MODELS, DETECTOR_FILE


def _rerun_cli():
    local = Path(sys.executable).parent / "rerun"
    return str(local) if local.exists() else shutil.which("rerun")


@pytest.mark.skipif(not (DEFAULT_MODELS / DETECTOR_FILE).exists()
                    or not (DEFAULT_MODELS / CLASSIFIER_FILE).exists(),
                    reason="the shipped perception models are missing")
def test_quick_demo_runs_end_to_end(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--quick", "--out", str(out)]) == 0
    results = json.loads((out / "results.json").read_text())
    assert set(results["methods"]) == {"mmap-birl", "map-birl", "hidden-data-em"}
    for r in results["methods"].values():
        (run,) = r["per_repeat"]
        assert [r[k] for k in ("tp", "fp", "tn", "fn")] == [run[k] for k in ("tp", "fp", "tn",
                                                                             "fn")]
        assert r["tp"] + r["fp"] + r["tn"] + r["fn"] == 10 and r["ile"] == run["ile"]
        low, high = r["precision_ci"]
        assert low <= r["precision"] <= high
    said = capsys.readouterr().out
    assert "| mmap-birl | paper (physical robot) | 23 | 2 | 18 | 7 |" in said
    assert "| map-birl | ours (simulation, 1 repeat(s)) |" in said

    sessions = sorted((out / "sessions").glob("*.mcap"))
    assert len(sessions) == 4
    for path in sessions:
        with path.open("rb") as fh:
            topics = {ch.topic for _, ch, _ in make_reader(fh, validate_crcs=True)
                      .iter_messages()}
        assert "/perception/state" in topics
    rrds = sorted(out.rglob("*.rrd"))
    assert {p.name for p in rrds} >= {"sessions.rrd", "learn.rrd", "evaluation.rrd"}
    cli = _rerun_cli()
    if cli is None:
        pytest.skip("the rerun CLI is not installed")
    for path in rrds:
        done = subprocess.run([cli, "rrd", "verify", str(path)], capture_output=True, text=True)
        assert done.returncode == 0, f"{path}: {done.stdout}{done.stderr}"

    # a second run into the same folder is refused rather than mixing two demos
    assert main(["demo", "--quick", "--out", str(out)]) == 2


def test_precision_and_recall_intervals_pool_repeats_and_contain_the_pooled_value():
    from onionsort.stages.demo import precision_recall_intervals

    # a perfect sort of 2 x 10 onions does not prove precision and recall are exactly 1
    (p_lo, p_hi), (r_lo, r_hi) = precision_recall_intervals([[6, 0, 4, 0], [6, 0, 4, 0]])
    assert p_hi == r_hi == 1.0 and 0.5 < p_lo < 1.0 and 0.5 < r_lo < 1.0
    counts = [[5, 1, 3, 1], [3, 0, 4, 3], [6, 2, 2, 0]]
    (p_lo, p_hi), (r_lo, r_hi) = precision_recall_intervals(counts, seed=1)
    assert p_lo < 14 / 17 < p_hi and r_lo < 14 / 18 < r_hi  # the pooled precision and recall
    assert precision_recall_intervals(counts, seed=1) == ((p_lo, p_hi), (r_lo, r_hi))
    # a repeat that never sorts a blemished onion out drags the recall interval down
    (_, _), (w_lo, w_hi) = precision_recall_intervals([*counts, [0, 0, 4, 6]], seed=1)
    assert w_lo < r_lo and w_hi < r_hi
    with pytest.raises(ValueError, match="shape"):
        precision_recall_intervals([[1, 2, 3]])


@pytest.mark.slow
@pytest.mark.skipif(not (DEFAULT_MODELS / DETECTOR_FILE).exists(),
                    reason="the shipped perception models are missing")
def test_quick_demo_with_repeats_reports_per_repeat_results_and_intervals(tmp_path):
    out = tmp_path / "demo"
    assert main(["demo", "--quick", "--repeats", "2", "--sessions", "2", "--out", str(out)]) == 0
    results = json.loads((out / "results.json").read_text())
    assert results["repeats"] == 2 and results["sessions"] == 2
    for r in results["methods"].values():
        assert [run["seed"] for run in r["per_repeat"]] == [0, 1]
        assert r["tp"] == sum(run["tp"] for run in r["per_repeat"])
        assert r["precision_ci"][0] <= r["precision"] <= r["precision_ci"][1]
        assert r["recall_ci"][0] <= r["recall"] <= r["recall_ci"][1]
    assert (out / "repeat_1" / "map-birl" / "evaluation.json").is_file()
