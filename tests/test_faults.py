"""Fault injection: ``record``, ``perceive``, ``dataset``, ``learn``, ``evaluate`` and ``train``
killed with SIGKILL at random moments leave every output complete and valid, or absent.

Each command runs once to the end while its output folder is watched (every change of a file
there counts; its outputs must pass the same checks), then is started afresh three times and
killed a random fraction of a second after a change drawn with seeds 0, 1 and 2 from the early,
middle and late part of that run's changes: moments when it is writing, which a kill at a
random time would mostly miss. After each kill:

- every file under the command's output folder is complete and valid, opened with the
  project's own readers (a session with the CRC-validating reader, or, for ``record``, which
  writes a session frame by frame, recoverable with ``recover=True`` as an interrupted
  recording is); only a ``*.partial`` temporary may be broken;
- ``perceive``, which rewrites sessions in place, leaves each one byte-identical or completely
  perceived;
- every input the command was given (sessions, calibration, run folder, dataset, models) is
  byte-identical.

Slow (a few minutes on two cores): ``pytest -m slow tests/test_faults.py -s`` prints a line per
kill and the tally.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from onionsort.stages.models import CALIBRATION_FILE, DEFAULT_MODELS

pytestmark = pytest.mark.slow

SEEDS = (0, 1, 2)
#: The part of a full run's output changes after which each seed's kill falls: early, middle,
#: late.
STRATA = ((0.0, 0.35), (0.35, 0.65), (0.65, 1.0))
PNG_END = b"IEND\xaeB`\x82"
TALLY: list[dict] = []


def _rerun_cli() -> str | None:
    local = Path(sys.executable).parent / "rerun"
    return str(local) if local.exists() else shutil.which("rerun")


def _digest(paths) -> dict[str, str]:
    """sha256 of every file under ``paths`` (files or folders)."""
    out = {}
    for root in map(Path, paths):
        for p in sorted([root] if root.is_file() else root.rglob("*")):
            if p.is_file():
                out[str(p)] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def _cli(*argv) -> list[str]:
    return [sys.executable, "-m", "onionsort.cli", *map(str, argv)]


def _snapshot(folder: Path) -> dict[str, tuple[int, int]]:
    """Size and modification time of every file under ``folder``."""
    out = {}
    for p in folder.rglob("*"):
        try:
            st = p.stat()
        except FileNotFoundError:  # renamed or removed meanwhile
            continue
        if p.is_file():
            out[str(p)] = (st.st_size, st.st_mtime_ns)
    return out


def _run(argv: list[str], out: Path, log: Path, kill_after: int | None = None,
         delay: float = 0.0) -> tuple[int, bool]:
    """Run ``argv`` while watching ``out``; with ``kill_after``, SIGKILL its process group
    ``delay`` seconds after the ``kill_after``-th change of the files under ``out``.

    Returns the number of changes seen and whether it was killed (False: it had finished).
    """
    changes, last = 0, _snapshot(out)
    with log.open("wb") as fh:
        proc = subprocess.Popen(argv, stdout=fh, stderr=fh, start_new_session=True)
        deadline = time.monotonic() + 600
        while proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
            now = _snapshot(out)
            if now != last:
                changes, last = changes + 1, now
            if kill_after is not None and changes >= kill_after:
                time.sleep(delay)
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(timeout=60)
                return changes, True
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            raise AssertionError(f"{argv} ran for more than 600 s")
    assert proc.returncode == 0, log.read_text()[-3000:]
    return changes, False


# --- what a valid file is, by kind ----------------------------------------------------------

def _session(path: Path, *, recoverable: bool) -> str:
    from recordings import open_session
    from recordings.session.reader import RecordingDamagedError

    try:
        session = open_session(path)
    except RecordingDamagedError:
        if not recoverable:
            raise
        session = open_session(path, recover=True)
        assert session.n_frames >= 0
        return "recoverable"
    assert session.status == "complete", f"{path}: {session.status}"
    return "complete"


def _png(path: Path) -> None:
    import cv2

    data = path.read_bytes()
    assert data.endswith(PNG_END), f"{path} is a truncated PNG"
    assert cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED) is not None, path


def _rrd(path: Path) -> None:
    done = subprocess.run([_rerun_cli(), "rrd", "verify", str(path)], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, f"{path}: {done.stdout}{done.stderr}"


def _checkpoint(path: Path) -> None:
    import torch

    from perception import Detector
    from state_abstraction.classifier import StateClassifier

    if path.name == "state_classifier.pt":
        StateClassifier.load(path)
    elif path.name == "detector.pt":
        Detector.load(path)
    else:
        ckpt = torch.load(path, map_location="cpu", weights_only=True)
        assert isinstance(ckpt, dict) and "model" in ckpt, path


def _check_tree(folder: Path, *, recoverable_sessions: bool = False) -> dict[str, int]:
    """Check every file under ``folder``; count them by what they were."""
    from onionsort.stages.learn import load_policy
    from recordings.labels.sorting_csv import read_tally

    seen: dict[str, int] = {}
    for path in sorted(folder.rglob("*")):
        if not path.is_file():
            continue
        if path.name.endswith(".partial"):  # a temporary of an interrupted write
            kind = "partial"
        elif path.suffix == ".mcap":
            kind = "session " + _session(path, recoverable=recoverable_sessions)
        elif path.suffix == ".png":
            _png(path)
            kind = "png"
        elif path.suffix == ".rrd":
            _rrd(path)
            kind = "rrd"
        elif path.suffix == ".pt":
            _checkpoint(path)
            kind = "checkpoint"
        elif path.suffix == ".json":
            doc = json.loads(path.read_text())
            kind = "json"
            if path.name == "model.json":
                load_policy(path.parent)
            elif path.name == "evaluation.json":
                assert len(doc["onions"]) == doc["n_onions"]
                assert doc["tp"] + doc["fp"] + doc["tn"] + doc["fn"] == doc["n_onions"]
        elif path.name == "tally.csv":  # one row an onion; written before evaluation.json
            kind = "tally"
            rows = read_tally(path)
            if (path.parent / "evaluation.json").is_file():
                evaluation = json.loads((path.parent / "evaluation.json").read_text())
                assert len(rows) == evaluation["n_onions"]
        else:
            raise AssertionError(f"an unexpected file {path}")
        seen[kind] = seen.get(kind, 0) + 1
    return seen


def _check_dataset(root: Path, frames: int) -> None:
    """A dataset folder, complete or not: every label record points at valid images; with
    dataset.json (written last) the whole dataset reads back with every frame."""
    from recordings.labels.dataset import SPLITS, read_metadata, read_split

    for split in SPLITS:
        for labels in ("labels.json", "inspection.json"):
            if (root / split / labels).exists():
                for record in json.loads((root / split / labels).read_text()):
                    for key in ("color", "depth"):
                        if key in record:
                            _png(root / split / record[key])
    if (root / "dataset.json").exists():
        meta = read_metadata(root)
        assert sum(meta["splits"].values()) == frames
        for split in SPLITS:
            assert len(list(read_split(root, split))) == meta["splits"][split]
            assert len(json.loads((root / split / "inspection.json").read_text())) == \
                meta["inspection_splits"][split]


# --- the commands, tiny ---------------------------------------------------------------------

@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Path:
    """Inputs for the commands: four short perceived sessions, a learned run, a small dataset
    (four, so that ``perceive``, which rewrites each in a moment after seconds of reading it,
    changes its outputs often enough to be killed in between)."""
    from onionsort.stages import (
        DatasetConfig,
        LearnConfig,
        PerceiveConfig,
        RecordConfig,
        learn,
        make_dataset,
        perceive,
        record,
    )

    if _rerun_cli() is None:
        pytest.skip("the rerun CLI (to verify .rrd files) is not installed")
    root = tmp_path_factory.mktemp("faults")
    record(RecordConfig(out=root / "rec", sessions=4, steps_per_session=4, occlusion=0.25,
                        seed=5))
    shutil.copytree(root / "rec", root / "perceived")
    sessions = tuple(sorted((root / "perceived").glob("*.mcap")))
    perceive(PerceiveConfig(sessions=sessions))
    learn(LearnConfig(sessions=sessions, calibration=DEFAULT_MODELS / CALIBRATION_FILE,
                      out=root / "run", rerun=False))
    make_dataset(DatasetConfig(out=root / "data", frames=60, steps_per_session=4,
                               robot_onions=0, seed=3))
    return root


def _commands(base: Path, work: Path) -> dict[str, dict]:
    """Each command: its argv, its output folder, its inputs, and how to check what it left."""
    perceived = sorted((base / "perceived").glob("*.mcap"))
    calibration = DEFAULT_MODELS / CALIBRATION_FILE
    return {
        "record": {
            "argv": _cli("record", "--sessions", 3, "--steps-per-session", 6, "--seed", 1,
                         "--out", work / "out", "--rerun", work / "out" / "sessions.rrd"),
            "inputs": [], "recoverable_sessions": True},
        "perceive": {
            "prepare": lambda: [shutil.copy(p, work / "out" / p.name)
                                for p in sorted((base / "rec").glob("*.mcap"))],
            "argv": _cli("perceive", *[work / "out" / p.name
                                      for p in sorted((base / "rec").glob("*.mcap"))]),
            "inputs": [DEFAULT_MODELS], "in_place": sorted((base / "rec").glob("*.mcap"))},
        "dataset": {
            "argv": _cli("dataset", "--frames", 72, "--steps-per-session", 4, "--robot-onions",
                         0, "--seed", 2, "--out", work / "out" / "data"),
            "inputs": [], "dataset": 72},
        "learn": {
            "argv": _cli("learn", *perceived, "--observation-model", calibration, "--out",
                         work / "out"),
            "inputs": [*perceived, calibration]},
        "evaluate": {
            "prepare": lambda: shutil.copytree(base / "run", work / "out", dirs_exist_ok=True),
            "argv": _cli("evaluate", work / "out", "--onions", 3, "--blemished", 2),
            "inputs": [work / "out" / "model.json", DEFAULT_MODELS]},
        "train state-classifier": {
            "argv": _cli("train", "state-classifier", "--data", base / "data", "--out",
                         work / "out", "--epochs", 6, "--batch-size", 8),
            "inputs": [base / "data"]},
        "train detector": {
            "argv": _cli("train", "detector", "--data", base / "data", "--out", work / "out",
                         "--epochs", 2, "--images-per-epoch", 16, "--batch-size", 8),
            "inputs": [base / "data"]},
    }


def _check_after(name: str, spec: dict, work: Path, before: dict[str, str]) -> dict[str, int]:
    """Every output valid or absent, every input as it was; what was found."""
    out = work / "out"
    found = _check_tree(out, recoverable_sessions=spec.get("recoverable_sessions", False)) \
        if out.exists() else {}
    if "dataset" in spec and (out / "data").exists():
        _check_dataset(out / "data", spec["dataset"])
    for original in spec.get("in_place", []):
        path = out / original.name
        if path.read_bytes() != original.read_bytes():
            from recordings import open_session

            session = open_session(path)
            assert session.perception and session.perception_models is not None, path
            assert sorted(session.perception) == list(range(len(session.step_frames())))
            found["perceived in place"] = found.get("perceived in place", 0) + 1
        else:
            found["untouched"] = found.get("untouched", 0) + 1
    after = _digest(spec["inputs"])
    changed = sorted(k for k in before if before[k] != after.get(k))
    assert not changed, f"{name} changed its inputs: {changed}"
    return found


@pytest.mark.parametrize("name", ["record", "perceive", "dataset", "learn", "evaluate",
                                  "train state-classifier", "train detector"])
def test_a_killed_command_leaves_every_file_valid_or_absent(base, tmp_path, name):
    work = tmp_path
    (work / "out").mkdir()
    spec = _commands(base, work)[name]
    if "prepare" in spec:
        spec["prepare"]()
    before = _digest(spec["inputs"])
    changes, _ = _run(spec["argv"], work / "out", work / "full.log")
    finished = _check_after(name, spec, work, before)
    assert "partial" not in finished, f"{name} finished but left a temporary: {finished}"
    assert changes >= 3, f"{name} changed its outputs {changes} times; nothing to kill into"
    kills = 0
    for seed, (low, high) in zip(SEEDS, STRATA, strict=True):
        rng = np.random.default_rng([seed, len(name)])
        kill_after = max(1, int(changes * rng.uniform(low, high)))
        delay = float(rng.uniform(0.0, 0.3))
        for _ in range(3):  # the run may change its files fewer times than the full one
            shutil.rmtree(work / "out")
            (work / "out").mkdir()
            if "prepare" in spec:
                spec["prepare"]()
            before = _digest(spec["inputs"])
            _, killed = _run(spec["argv"], work / "out", work / f"kill{seed}.log", kill_after,
                             delay)
            found = _check_after(name, spec, work, before)
            if killed:
                break
            kill_after = max(1, kill_after // 2)
        kills += killed
        TALLY.append({"command": name, "seed": seed, "after_changes": kill_after,
                      "killed": killed, "left": found})
        print(f"{name}: seed {seed}, {'killed' if killed else 'finished before'} "
              f"{delay:.2f} s after output change {kill_after} of {changes}; valid: {found}")
    assert kills == len(SEEDS), f"{name} finished before {len(SEEDS) - kills} kill(s)"


def _robot_views_started(out: Path) -> bool:
    for split in ("train", "val", "test"):
        try:
            records = json.loads((out / split / "inspection.json").read_text())
        except (OSError, ValueError):
            continue
        if any(r.get("source") == "robot" for r in records):
            return True
    return False


def test_a_dataset_killed_while_rendering_the_robots_views_does_not_read_as_complete(tmp_path):
    out = tmp_path / "data"
    argv = _cli("dataset", "--frames", 36, "--steps-per-session", 4, "--robot-onions", 30,
                "--robot-views", 3, "--seed", 4, "--out", out)
    with (tmp_path / "log").open("wb") as fh:
        proc = subprocess.Popen(argv, stdout=fh, stderr=fh, start_new_session=True)
        deadline = time.monotonic() + 300
        while not _robot_views_started(out) and proc.poll() is None \
                and time.monotonic() < deadline:
            time.sleep(0.02)
        running = proc.poll() is None  # killed after the first of the three line-ups
        if running:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=60)
    assert running, "the dataset finished before the kill; nothing was tested"
    if (out / "dataset.json").exists():
        _check_dataset(out, 36)
        robot = sum(r.get("source") == "robot" for split in ("train", "val", "test")
                    for r in json.loads((out / split / "inspection.json").read_text()))
        assert robot == 30 * 3, f"dataset.json marks a dataset with {robot} of 90 robot views"


def test_the_tally(request):
    """Print what the kills above found (run with ``-s``)."""
    if not TALLY:
        pytest.skip("no command was killed in this run")
    killed = [t for t in TALLY if t["killed"]]
    print(f"\n{len(killed)} kills injected, {len(killed)} left every file valid or absent; "
          f"{sum('partial' in t['left'] for t in killed)} left a *.partial temporary, "
          f"{sum(bool(set(t['left']) - {'partial'}) for t in killed)} left outputs")
    assert killed
