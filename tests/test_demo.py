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
    assert set(results["methods"]) == {"mmap-birl", "hidden-data-em"}
    for r in results["methods"].values():
        assert r["tp"] + r["fp"] + r["tn"] + r["fn"] == 10
        assert 0.0 <= r["precision"] <= 1.0 and 0.0 <= r["recall"] <= 1.0
    assert "| mmap-birl | paper (physical robot) | 23 | 2 | 18 | 7 |" in capsys.readouterr().out
    assert all(r["ile"] >= 0.0 for r in results["methods"].values())

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
