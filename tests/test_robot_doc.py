"""docs/robot.md: the walk from a learning run to a lab's Table 1 row runs on simulated data.

A learn run of two methods with their posteriors; a line-up recorded from the simulator (the
page's command, fewer onions); the runtime on its views; the loop and the logging with a
replayed line-up in the arm's place (the ROS 2 class, examples/ros2_arm.py, is only parsed:
it needs ROS 2); ``evaluate --lineup`` and ``score`` as the page shows them; and a tally
counted by hand.
"""

from __future__ import annotations

import ast
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from onionsort.cli import main
from onionsort.stages.models import CALIBRATION_FILE, DEFAULT_MODELS
from tests.doccheck import doc_commands, fenced_blocks

ROOT = Path(__file__).resolve().parent.parent
PAGE = ROOT / "docs" / "robot.md"
#: the page's ROS 2 arm class, only parsed here (it needs ROS 2)
ARM = ROOT / "examples" / "ros2_arm.py"
#: the page's line-up, smaller
SMALLER = {("--onions", "20"): ("--onions", "3"), ("--blemished", "10"): ("--blemished", "1")}


def _smaller(argv: tuple[str, ...]) -> list[str]:
    out, i = [], 0
    while i < len(argv):
        pair = tuple(argv[i:i + 2])
        out += SMALLER.get(pair, pair[:1])
        i += 2 if pair in SMALLER else 1
    return out


def _python_blocks() -> list[str]:
    return ["\n".join(b.lines) for b in fenced_blocks(PAGE.read_text()) if b.info == "python"]


def _walk_commands() -> list[tuple[str, ...]]:
    """The page's commands of the walk (the measurement's own, full size, are left out)."""
    return [c.argv for c in doc_commands(PAGE) if not c.inline and "lineup-7" in c.text]


def test_the_ros2_arm_class_is_python_and_a_complete_cell():
    arm = ARM.read_text()
    assert f"]({ARM.relative_to(ROOT).as_posix()})" in PAGE.read_text().replace("../", "")
    tree = ast.parse(arm)
    (cls,) = [n for n in tree.body if isinstance(n, ast.ClassDef)]
    members = {n.name for n in cls.body if isinstance(n, ast.FunctionDef)}
    assert {"state", "focus", "execute", "inspect", "defer", "fate"} <= members


@pytest.mark.slow
def test_every_step_of_the_robot_walk_runs(tmp_path, monkeypatch, perceived_sessions, capsys):
    from robot.replay import ReplayedLineup

    monkeypatch.chdir(tmp_path)
    assert main(["learn", *map(str, perceived_sessions), "--method", "mmap-birl,map-birl",
                 "--posterior", "--samples", "200", "--posterior-method", "laplace",
                 "--observation-model", str(DEFAULT_MODELS / CALIBRATION_FILE),
                 "--allow-model-mismatch", "--out", "runs/learn"]) == 0
    shutil.copytree(DEFAULT_MODELS, "runs/lab-models")  # the lab's models folder
    record, replay, *scores = _walk_commands()
    assert record[:3] == ("evaluate", "--policy", "expert") and "--lineup" in replay
    assert [s[0] for s in scores] == ["score", "score"]
    assert main(_smaller(record)) == 0
    from onionsort.stages.lineup import read_recording

    (lineup,) = read_recording(Path("runs/lineup-7"))
    assert lineup.lineup == 7 and lineup.n_onions == 3
    runtime, loop, logging = _python_blocks()
    scope: dict = {"views": lineup.load(0)}
    exec(compile(runtime, "docs/robot.md (the runtime)", "exec"), scope)
    assert scope["verdict"].p_blemished is not None
    scope["cell"] = ReplayedLineup(lineup.n_onions, lineup.load)
    exec(compile(loop.replace("SortingRun(cell, 20,", f"SortingRun(cell, {lineup.n_onions},"),
                 "docs/robot.md (the loop)", "exec"), scope)
    tally = scope["run"].tally  # every onion sorted or handed to a person
    assert tally.complete and set(tally.fates) <= {"bin", "line", "tray"}
    Path("runs/arm").mkdir()
    scope["cell"] = ReplayedLineup(lineup.n_onions, lineup.load)
    scope["latest_image"] = lambda: np.zeros((240, 320, 3), np.uint8)  # the main camera
    exec(compile(logging.replace("SortingRun(cell, 20,", f"SortingRun(cell, {lineup.n_onions},"),
                 "docs/robot.md (logging)", "exec"), scope)
    from recordings import open_session

    session = open_session(Path("runs/arm/run.mcap"))
    assert session.n_frames == scope["run"].n_steps
    assert Path("runs/arm/run.rrd").stat().st_size > 1000
    capsys.readouterr()
    assert main(list(replay)) == 0
    for method in ("mmap-birl", "map-birl"):
        assert (Path("runs/learn") / method / "tally.csv").is_file()
    assert main([*scores[0]]) == 0
    assert main([*scores[1]]) == 0
    scored = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    evaluation = json.loads(Path("runs/learn/mmap-birl/evaluation.json").read_text())
    assert {k: scored[k] for k in ("tp", "fp", "tn", "fn", "precision_ci", "deferred")} == {
        k: evaluation[k] for k in ("tp", "fp", "tn", "fn", "precision_ci", "deferred")}
    # a tally counted by hand, as the page shows one, scored against its truth
    hand = next(b for b in fenced_blocks(PAGE.read_text())
                if b.info == "csv" and b.lines[0].startswith("lineup,index,fate"))
    Path("hand.csv").write_text("\n".join(hand.lines) + "\n")
    Path("truth.csv").write_text("lineup,index,class\n0,0,blemished\n0,1,good\n0,2,good\n")
    assert main(["score", "hand.csv", "--truth", "truth.csv", "--json"]) == 0
    counted = json.loads(capsys.readouterr().out)
    assert (counted["tp"], counted["tn"], counted["deferred"]) == (1, 1, 1)
    assert np.isclose(counted["precision"], 1.0)
