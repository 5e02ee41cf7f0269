"""docs/lab.md: every command of the walk from a lab's camera to a learned policy runs, in its
order, on a small made-up lab: simulated sessions turned into plain videos (the line and the
inspection spot), their ground truth kept aside to play the person who corrects the labels."""

from __future__ import annotations

import contextlib
import csv
import glob
import io
import json
import os
import re
import shutil
from pathlib import Path

import pytest

from onionsort.cli import main
from recordings import open_session
from recordings.sources.video import write_video
from tests.doccheck import doc_commands

ROOT = Path(__file__).resolve().parent.parent
#: What the walk's numbers become on the made-up lab (the commands are otherwise as written).
SMALLER = {("--frames", "3000"): ["--frames", "36", "--steps-per-session", "4",
                                  "--robot-onions", "10", "--robot-views", "2"],
           ("--frames", "240"): ["--frames", "18"], ("--epochs", "6"): ["--epochs", "1"],
           ("--epochs", "4"): ["--epochs", "1"]}
#: The walk is docs/lab.md's numbered sections (``## 1. Record the line`` ...); the sections
#: after them explain and measure, with commands of their own at full size.
WALK_SECTION = re.compile(r"## \d+\. ")
#: The lab's sessions: to label for training, held out to label for calibration, to learn from.
USES = {"train-line": 3, "heldout-line": 3, "line": 2}


def _smaller(argv: tuple[str, ...]) -> list[str]:
    out, i = [], 0
    while i < len(argv):
        pair = tuple(argv[i:i + 2])
        if pair in SMALLER:
            out += SMALLER[pair]
            i += 2
        else:
            out.append(argv[i])
            i += 1
    if argv[:2] == ("train", "detector"):
        out += ["--images-per-epoch", "16"]
    return out


def _expanded(argv: list[str]) -> list[str]:
    return [p for a in argv for p in (sorted(glob.glob(a)) if "*" in a else [a])]


def _correct(task: Path, truth: dict) -> None:
    """A person's corrections: every row of the task's states.csv set to the truth."""
    for path in (task / "states.csv", task / "inspection" / "states.csv"):
        if not path.is_file():
            continue
        rows = list(csv.DictReader(path.read_text().splitlines()))
        for row in rows:
            state = truth[int(row["session"]), int(row["frame"])]
            row.update(occluded=int(state["occluded"]), onion=state["onion"],
                       end_effector=state["end_effector"], prediction=state["prediction"],
                       action=state["action"])
        with path.open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)


@pytest.mark.slow
def test_every_command_of_the_lab_walk_runs(tmp_path, monkeypatch):
    from irl.domains.onion_sorting import SORTING_TASK

    lines = (ROOT / "docs" / "lab.md").read_text().splitlines()
    # the walk ends at the first heading after its last numbered section
    last = max(i for i, line in enumerate(lines) if WALK_SECTION.match(line))
    end = next((i + 1 for i, line in enumerate(lines[last + 1:], last + 1)
                if line.startswith("## ")), len(lines) + 1)
    commands = [c for c in doc_commands(ROOT / "docs" / "lab.md")
                if not c.inline and c.line < end]
    monkeypatch.chdir(tmp_path)
    os.symlink(ROOT / "onionsort", tmp_path / "onionsort")  # onionsort/models/...
    n = sum(USES.values())
    assert main(["record", "--sessions", str(n), "--steps-per-session", "6", "--occlusion",
                 "0.2", "--seed", "61", "--out", "sim"]) == 0
    sessions = sorted(Path("sim").glob("*.mcap"))
    truth, k = {}, 0
    (import_cmd,) = [c for c in commands if c.argv[0] == "import"]
    for use, count in USES.items():
        for i in range(count):
            frames = list(open_session(sessions[k]).frames())
            views = {f.step: f.inspection for f in frames if f.inspection is not None}
            write_video("line.mp4", (f.color for f in frames), fps=1.5)
            write_video("face.mp4", (views[f.step] for f in frames), fps=1.5)
            argv = [a.replace("runs/line/session_000", f"runs/{use}/session_{i:03d}")
                    for a in import_cmd.argv]
            assert main(argv) == 0, argv
            for f in frames:
                truth[use, i, f.index] = {**f.state,
                                          "action": SORTING_TASK.action_names[f.state["action"]]}
            k += 1
    ran = ["import"]
    for command in commands:
        if command.argv[0] == "import":
            continue
        argv = _expanded(_smaller(command.argv))
        target = re.search(r"\s>\s*(\S+)\s*$", command.text)  # `... --json > FILE`
        printed = io.StringIO()
        with contextlib.redirect_stdout(printed) if target else contextlib.nullcontext():
            assert main(argv) == 0, command.text
        if target:
            Path(target.group(1)).write_text(printed.getvalue())
        ran.append(" ".join(command.argv[:2]))
        if command.argv[:2] == ("label", "select"):  # a person labels what it chose
            use = next(u for u in USES if any(f"runs/{u}/" in a for a in command.argv))
            _correct(Path(argv[argv.index("--out") + 1]),
                     {(s, f): v for (u, s, f), v in truth.items() if u == use})
    assert ran == ["import", "label select", "label import", "dataset --frames",
                   "train detector", "train state-classifier", "train inspection",
                   "label select", "label import", "calibrate --data",
                   "eval-perception --data", "eval-perception --data",
                   "compare-perception --base", "perceive runs/line/*.mcap",
                   "learn runs/line/*.mcap"]
    assert json.loads(Path("runs/heldout-lab.json").read_text())["n_steps"] > 0
    assert Path("runs/lab-learn/model.json").is_file()
    shutil.rmtree("runs")
