"""End to end: ``onionsort record`` on a tiny configuration, with a Rerun file."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from irl.demonstrations import Demonstration
from onionsort.cli import main
from recordings import open_session, read_demonstrations


def _rerun() -> str | None:
    local = Path(sys.executable).parent / "rerun"
    return str(local) if local.exists() else shutil.which("rerun")


def test_record_writes_readable_sessions_and_a_verified_rrd(tmp_path):
    out, rrd = tmp_path / "rec", tmp_path / "rec" / "sessions.rrd"
    argv = ["record", "--sessions", "2", "--steps-per-session", "4", "--frames-per-step", "1",
            "--occlusion", "0.5", "--seed", "3", "--out", str(out), "--rerun", str(rrd)]
    assert main(argv) == 0
    paths = sorted(out.glob("session_*.mcap"))
    assert [p.name for p in paths] == ["session_000.mcap", "session_001.mcap"]
    demos = read_demonstrations(paths)
    assert all(isinstance(d, Demonstration) and len(d) == 4 for d in demos)
    meta = open_session(paths[1]).metadata
    assert meta["seed"] == 3 and meta["session_index"] == 1
    assert meta["config"]["occlusion"] == 0.5 and meta["software"].startswith("onionsort")
    assert rrd.stat().st_size > 0
    rerun = _rerun()
    if rerun is None:
        pytest.skip("the rerun CLI is not installed")
    for cmd in (["rrd", "verify", str(rrd)], ["mcap", "check", str(paths[0])]):
        result = subprocess.run([rerun, *cmd], capture_output=True, text=True)
        assert result.returncode == 0, result.stdout + result.stderr

    # the same seed gives the same sessions; existing files are not overwritten silently
    assert main([*argv[:-2]]) == 2
    again = tmp_path / "again"
    assert main([*argv[:-4], "--out", str(again)]) == 0
    assert read_demonstrations(sorted(again.glob("*.mcap"))) == demos


def test_record_rejects_bad_arguments(tmp_path, capsys):
    assert main(["record", "--sessions", "0", "--out", str(tmp_path)]) == 2
    assert "sessions must be >= 1; got 0" in capsys.readouterr().err
    assert main(["record", "--occlusion", "1.5", "--out", str(tmp_path)]) == 2
    assert "occlusion must be in [0, 1]" in capsys.readouterr().err
