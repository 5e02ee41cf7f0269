"""A lab's recorded line-up at the command line: ``evaluate --record-lineup`` records one,
``evaluate --lineup --truth`` replays any policy on it with the live run's counts, ``tally.csv``
beside ``evaluation.json``, and ``score`` counting a tally as ``evaluate`` did; bad input is one
line, exit code 2 and no output file."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from irl.domains.onion_sorting import SortAction, onion_sorting
from onionsort.cli import main

#: the small line-up of the tests: onions, blemished ones, seed, level
ONIONS, BLEMISHED, SEED, LEVEL = 4, 2, 5, "hard"


def _learn_run(folder: Path, policy: np.ndarray, method: str = "made-up") -> Path:
    """A learn run folder with only the policy (what ``evaluate`` reads of one)."""
    folder.mkdir(parents=True)
    (folder / "model.json").write_text(json.dumps({"method": method,
                                                   "policy_indices": policy.tolist()}))
    return folder


def _swapped() -> np.ndarray:
    """The expert's policy with its two places swapped: good onions binned, blemished kept."""
    expert = onion_sorting().expert_policy().argmax(axis=1)
    out = expert.copy()
    bin_, line = int(SortAction.PLACE_IN_BIN), int(SortAction.PLACE_ON_CONVEYOR)
    out[expert == bin_], out[expert == line] = line, bin_
    return out


def _json(capsys) -> dict:
    return json.loads(capsys.readouterr().out.strip().splitlines()[-1])


def _fates(tally: Path) -> list[tuple]:
    return [(r["lineup"], r["index"], r["fate"], r["call"])
            for r in csv.DictReader(tally.read_text().splitlines())]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """``(folder, recording)``: the expert's run with the shipped models, every view recorded."""
    d = tmp_path_factory.mktemp("lineup")
    assert main(["evaluate", "--policy", "expert", "--onions", str(ONIONS), "--blemished",
                 str(BLEMISHED), "--seed", str(SEED), "--difficulty", LEVEL, "--record-lineup",
                 str(d / "rec"), "--out", str(d / "expert"), "--no-rerun", "--no-mcap"]) == 0
    return d, d / "rec"


def test_a_recorded_lineup_holds_every_view_and_the_truth(recorded):
    d, rec = recorded
    rows = list(csv.DictReader((rec / "lineups.csv").read_text().splitlines()))
    assert {(int(r["index"]), int(r["view"])) for r in rows} == {
        (i, v) for i in range(ONIONS) for v in range(5)}
    assert {r["lineup"] for r in rows} == {str(SEED)}
    assert all((rec / "images" / r["image"]).is_file() for r in rows)
    truth = list(csv.DictReader((rec / "truth.csv").read_text().splitlines()))
    assert sum(r["class"] == "blemished" for r in truth) == BLEMISHED
    evaluation = json.loads((d / "expert" / "evaluation.json").read_text())
    assert evaluation["every_view"] is True and evaluation["lineups"] == [SEED]
    assert [o["blemished"] for o in evaluation["onions"]] == [
        r["class"] == "blemished" for r in truth]


def test_score_counts_a_tally_as_evaluate_did(recorded, capsys):
    d, rec = recorded
    evaluation = json.loads((d / "expert" / "evaluation.json").read_text())
    assert main(["score", str(d / "expert" / "tally.csv"), "--truth", str(rec / "truth.csv"),
                 "--json"]) == 0
    scored = _json(capsys)
    keys = ("tp", "fp", "tn", "fn", "precision", "recall", "precision_ci", "recall_ci",
            "deferred")
    assert {k: scored[k] for k in keys} == {k: evaluation[k] for k in keys}
    assert main(["score", str(d / "expert" / "tally.csv"), "--truth",
                 str(rec / "truth.csv")]) == 0
    assert "precision" in capsys.readouterr().out


def test_a_replayed_policy_sorts_as_it_does_live(recorded, capsys):
    """Another policy than the one that recorded (it bins the good onions), replayed on the
    recording and sorting the same seed live with every view: the same fates and calls."""
    d, rec = recorded
    run = _learn_run(d / "learned", _swapped())
    assert main(["evaluate", str(run), "--lineup", str(rec), "--truth", str(rec / "truth.csv"),
                 "--out", str(d / "replayed"), "--json"]) == 0
    replayed = _json(capsys)
    assert main(["evaluate", str(run), "--every-view", "--onions", str(ONIONS), "--blemished",
                 str(BLEMISHED), "--seed", str(SEED), "--difficulty", LEVEL, "--out",
                 str(d / "live"), "--no-rerun", "--no-mcap", "--json"]) == 0
    live = _json(capsys)
    counts = ("tp", "fp", "tn", "fn", "deferred")
    assert {k: replayed[k] for k in counts} == {k: live[k] for k in counts}
    assert live["fp"] > 0  # it binned good onions: not the recording's own run
    assert _fates(d / "replayed" / "tally.csv") == _fates(d / "live" / "tally.csv")
    assert sorted(p.name for p in (d / "replayed").iterdir()) == ["evaluation.json",
                                                                   "tally.csv"]


def _recording(folder: Path, onions=(0, 1, 2), views: int = 2) -> Path:
    """A recorded line-up without the simulator: small random views of ``onions``."""
    import cv2

    (folder / "images").mkdir(parents=True)
    rng = np.random.default_rng(0)
    lines = ["split,image,lineup,index,view"]
    for i in onions:
        for v in range(views):
            name = f"o{i}-v{v}.png"
            cv2.imwrite(str(folder / "images" / name), rng.integers(0, 255, (24, 32, 3),
                                                                    np.uint8))
            lines.append(f",{name},0,{i},{v}")
    (folder / "lineups.csv").write_text("\n".join(lines) + "\n")
    return folder


def _truth(path: Path, rows) -> Path:
    path.write_text("lineup,index,class\n" + "".join(f"{a},{b},{c}\n" for a, b, c in rows))
    return path


GOOD3 = [(0, 0, "good"), (0, 1, "blemished"), (0, 2, "good")]


@pytest.mark.parametrize(("case", "words"), [
    ("missing", "gives no class for line-up 0: onion 2 of the line-up(s) of"),
    ("unknown", "names line-up 0: onion 3, which the line-up(s) of"),
    ("class", "line 3: class must be good or blemished; got 'rotten'"),
    ("no views", "onion 1 of line-up 0 has no views"),
    ("no model", "holds no learned model (no model.json)"),
    ("no image", "image 'o0-v0.png' is not in"),
])
def test_bad_lineup_input_is_one_line_exit_2_and_no_output(tmp_path, capsys, case, words):
    rec = _recording(tmp_path / "rec", onions=(0, 2) if case == "no views" else (0, 1, 2))
    rows = {"missing": GOOD3[:2], "unknown": [*GOOD3, (0, 3, "good")],
            "class": [GOOD3[0], (0, 1, "rotten"), GOOD3[2]]}.get(case, GOOD3)
    truth = _truth(tmp_path / "truth.csv", rows)
    if case == "no image":
        (rec / "images" / "o0-v0.png").unlink()
    run = tmp_path / "run"
    if case == "no model":
        run.mkdir()
    else:
        _learn_run(run, onion_sorting().expert_policy().argmax(axis=1))
    before = sorted(p.name for p in run.iterdir())
    code = main(["evaluate", str(run), "--lineup", str(rec), "--truth", str(truth), "--out",
                 str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and words in err[0], err
    assert not (tmp_path / "out").exists() and sorted(p.name for p in run.iterdir()) == before


@pytest.mark.parametrize(("tally", "words"), [
    ("0,0,bin,,,0\n0,1,line,,,0\n0,2,line,,,0\n", None),
    ("7,0,bin,,,0\n7,1,line,,,0\n7,2,line,,,0\n",
     "it lacks line-up 0: onions 0-2; it holds line-up 7: onions 0-2): a tally from another "
     "line-up?"),
    ("0,0,bin,,,0\n0,1,line,,,0\n", "it lacks line-up 0: onion 2"),
    ("0,0,bin,,,0\n0,1,floor,,,0\n0,2,line,,,0\n", "line 3: fate must be one of bin, line, "
                                                   "tray; got 'floor'"),
])
def test_score_refuses_a_tally_of_other_onions(tmp_path, capsys, tally, words):
    """A person's count of the bins (no calls): scored, or refused in one line, exit 2."""
    path = tmp_path / "tally.csv"
    path.write_text("lineup,index,fate,call,p_blemished,deferred\n" + tally)
    truth = _truth(tmp_path / "truth.csv", GOOD3)
    code = main(["score", str(path), "--truth", str(truth), "--json"])
    out, err = capsys.readouterr()
    if words is None:
        assert code == 0 and json.loads(out) == {
            "tp": 0, "fp": 1, "tn": 1, "fn": 1, "precision": 0.0, "recall": 0.0,
            "precision_ci": [0.0, pytest.approx(0.7934506, abs=1e-6)],
            "recall_ci": [0.0, pytest.approx(0.7934506, abs=1e-6)], "deferred": 0,
            "deferral_rate": 0.0}
        return
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1 and words in err, err


def test_the_lineup_options_go_together(tmp_path, capsys):
    rec = _recording(tmp_path / "rec")
    truth = _truth(tmp_path / "truth.csv", GOOD3)
    for argv, words in (
            (["--lineup", str(rec)], "--lineup SOURCE and --truth FILE.csv go together"),
            (["--truth", str(truth)], "--truth names the classes of a recorded line-up"),
            (["--lineup", str(rec), "--truth", str(truth), "--record-lineup",
              str(tmp_path / "again")], "give one of them")):
        code = main(["evaluate", "--policy", "expert", "--out", str(tmp_path / "out"), *argv])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and words in err[0], err
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("")
    code = main(["evaluate", "--policy", "expert", "--record-lineup", str(tmp_path / "full"),
                 "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and "is not an empty folder" in err[0]
    assert not (tmp_path / "out").exists()


def test_a_recording_exported_as_coco_or_yolo_is_found(tmp_path):
    """Images under ``<split>/`` (COCO) or ``images/<split>/`` (YOLO), and the export's root
    with ``inspection/``: the views are found."""
    from onionsort.stages.lineup import read_recording

    rec = _recording(tmp_path / "flat")
    for layout in ("test", "images/test"):
        root = tmp_path / layout.replace("/", "-") / "inspection"
        (root / layout).mkdir(parents=True)
        for png in (rec / "images").iterdir():
            shutil.copy(png, root / layout / png.name)
        text = (rec / "lineups.csv").read_text().replace("\n,", "\ntest,")
        (root / "lineups.csv").write_text(text)
        (lineup,) = read_recording(root.parent)
        assert lineup.lineup == 0 and lineup.n_onions == 3
        assert [len(v) for v in lineup.views] == [2, 2, 2]
        assert lineup.load(1)[0].shape == (24, 32, 3)
