"""``onionsort label select``: the least-sure frames of recorded sessions, spread over
sessions and steps, as a pre-annotated labelling task that ``label import`` reads back."""

import json

import numpy as np
import pytest

from onionsort.cli import main
from onionsort.stages.label_select import _choose
from recordings.dataset import read_records, split_sessions


@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    out = tmp_path_factory.mktemp("select") / "rec"
    assert main(["record", "--sessions", "3", "--steps-per-session", "6", "--seed", "41",
                 "--workers", "1", "--out", str(out)]) == 0
    return sorted(out.glob("*.mcap"))


def test_the_choice_takes_the_least_sure_in_rounds_over_sessions():
    scores = [[0.1, 5.0, 4.0, 0.2], [3.0, 0.0, 0.0, 0.0]]
    # round 1: session 0's step 1 (5.0), session 1's step 0 (3.0); round 2: session 0's
    # step 2 (4.0), then session 1's least sure left (step 1, the first of equals)
    assert _choose(scores, 1, 4) == [(0, 1), (1, 0), (0, 2), (1, 1)]
    assert _choose(scores, 1, 8) == [(0, 1), (1, 0), (0, 2), (1, 1), (0, 3), (1, 2), (0, 0),
                                     (1, 3)]
    assert _choose(scores, 3, 7) == [(0, 1), (1, 0), (0, 2)]  # whole steps up to 7 frames
    assert _choose([[1.0], [2.0, 3.0]], 1, 9) == [(1, 1), (0, 0), (1, 0)]  # then none left


def test_coco_selection_is_pre_annotated_and_comes_back_through_label_import(sessions,
                                                                             tmp_path):
    out = tmp_path / "task"
    assert main(["label", "select", *map(str, sessions), "--frames", "12", "--device", "cpu",
                 "--out", str(out)]) == 0
    chosen = json.loads((out / "selection.json").read_text())["frames"]
    assert len(chosen) == 12
    steps = {(f["session"], f["step"]) for f in chosen}
    assert len(steps) == 4 and {s for s, _ in steps} == {0, 1, 2}  # spread over sessions
    doc = json.loads((out / "annotations" / "instances_default.json").read_text())
    assert sorted(im["file_name"] for im in doc["images"]) == sorted(f["image"] for f in chosen)
    assert all({"session", "step", "frame"} <= set(im) for im in doc["images"])
    assert all(0.0 < a["score"] <= 1.0 for a in doc["annotations"])
    lines = (out / "states.csv").read_text().splitlines()
    assert len(lines) == 13 and lines[1].startswith(",")  # no split: label import splits
    back = tmp_path / "lab"
    assert main(["label", "import", str(out), "--format", "coco", "--out", str(back)]) == 0
    assert [s for _, s in split_sessions(back, "all")] == [0, 1, 2]
    assert sum(len(read_records(back, s)) for s in ("train", "val", "test")) == 12


def test_label_studio_tasks_carry_predictions_and_where_each_frame_is(sessions, tmp_path):
    out = tmp_path / "ls"
    assert main(["label", "select", *map(str, sessions[:2]), "--frames", "6", "--format",
                 "labelstudio", "--device", "cpu", "--out", str(out)]) == 0
    tasks = json.loads((out / "tasks.json").read_text())
    assert len(tasks) == 6
    config = (out / "labeling_config.xml").read_text()
    for task in tasks:
        assert {"image", "session", "step", "frame"} <= set(task["data"])
        assert (out / task["data"]["image"]).is_file()
        (prediction,) = task["predictions"]
        kinds = {r["from_name"]: r for r in prediction["result"]}
        assert {"onion", "end_effector", "prediction", "action", "occluded"} <= set(kinds)
        for r in prediction["result"]:
            assert f'name="{r["from_name"]}"' in config
            if r["type"] == "rectanglelabels":
                v = r["value"]
                assert v["x"] >= 0 and v["x"] + v["width"] <= 100 + 1e-6
                assert r["value"]["rectanglelabels"][0] in ("good", "blemished")
            else:
                assert f'value="{r["value"]["choices"][0]}"' in config


def test_zero_frames_is_one_line(sessions, tmp_path, capsys):
    assert main(["label", "select", str(sessions[0]), "--frames", "0",
                 "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == ["onionsort label: error: frames must be >= 1; got 0"]
    assert not (tmp_path / "x").exists()


def _wrong_steps(paths, models) -> dict:
    """``(session, step) -> bool``: the step's state guess is wrong (the truth, which the
    selection never reads, checks it)."""
    from recordings.reader import open_session

    wrong = {}
    for k, path in enumerate(paths):
        session = open_session(path)
        steps = session.step_frames()
        seen = models.perceive([([f.color for f in st], [f.depth for f in st],
                                 [f.inspection if f.inspection_png is not None else None
                                  for f in st]) for st in steps])
        for st, guess in zip(steps, seen, strict=True):
            truth = st[0].state
            wrong[k, st[0].step] = bool(guess.occluded != truth["occluded"] or (
                not truth["occluded"] and guess.state != truth["state"]))
    return wrong


@pytest.mark.slow
def test_the_frames_chosen_are_wrong_three_times_as_often(tmp_path, capsys):
    """Acceptance on 6 fresh `paper` sessions of 20 steps (seed 902): the 60 frames chosen
    have a wrong state guess at least 3x as often as the sessions' steps on average. (Not
    met: where fewer than 20 steps are wrong, that all are among the 20 chosen; docs/lab.md
    gives the count.)"""
    from onionsort.stages.label_select import LabelSelectConfig, select_frames
    from onionsort.stages.models import PerceptionModels

    assert main(["record", "--sessions", "6", "--steps-per-session", "20", "--difficulty",
                 "paper", "--seed", "902", "--out", str(tmp_path / "rec")]) == 0
    paths = sorted((tmp_path / "rec").glob("*.mcap"))
    models = PerceptionModels.load(None, "cpu")
    wrong = _wrong_steps(paths, models)
    chosen = select_frames(LabelSelectConfig(sessions=tuple(paths), out=tmp_path / "task",
                                             frames=60, device="cpu"), models=models)
    picked = {(f["session"], f["step"]) for f in chosen["frames"]}
    rate, rate_picked = (np.mean(list(wrong.values())),
                         np.mean([wrong[s] for s in picked]))
    with capsys.disabled():
        print(f"\n{sum(wrong.values())} of {len(wrong)} steps wrong ({rate:.3f}); "
              f"{sum(wrong[s] for s in picked)} of the {len(picked)} chosen ({rate_picked:.3f})")
    assert rate_picked >= 3 * rate
