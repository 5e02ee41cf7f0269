"""``bench/through_camera.py``: a dataset written as one other camera would have taken it."""

import json

import cv2
import numpy as np
import pytest

from bench.through_camera import main, through_camera
from onionsort.cli import main as onionsort
from perception.camera_shift import CameraShift
from recordings.labels.dataset import SPLITS, read_metadata, read_records, read_steps


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """A small rendered dataset: 4 sessions of 4 steps of 3 frames, and the Sawyer's views."""
    out = tmp_path_factory.mktemp("through") / "data"
    assert onionsort(["dataset", "--frames", "48", "--steps-per-session", "4",
                      "--robot-onions", "10", "--robot-views", "2", "--seed", "5",
                      "--val", "0.25", "--test", "0.25", "--workers", "1",
                      "--out", str(out)]) == 0
    return out


def _rgb(path):
    return cv2.cvtColor(cv2.imread(str(path), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


def test_every_image_goes_through_one_camera_and_the_rest_is_copied(rendered, tmp_path):
    out = tmp_path / "cam"
    assert main([str(rendered), "--camera", "3737", "--out", str(out)]) == 0
    camera = CameraShift.draw(3737)
    sessions, changed = set(), 0
    for split in SPLITS:
        for view in ("camera", "inspection"):
            records = read_records(out, split, view)
            assert records == read_records(rendered, split, view)
            for rec in records:
                original = _rgb(rendered / split / rec["color"])
                shifted = _rgb(out / split / rec["color"])
                # the same camera for every session and line-up
                assert np.array_equal(shifted, camera.apply(original))
                changed += int(not np.array_equal(shifted, original))
                sessions.add(rec.get("session"))
                if "depth" in rec:
                    assert (out / split / rec["depth"]).read_bytes() == \
                        (rendered / split / rec["depth"]).read_bytes()
    assert len(sessions - {None}) == 4 and changed > 0
    meta = read_metadata(out)
    assert meta["camera_shift"] == {"seed": 3737, **camera.to_dict()}
    assert meta["splits"] == read_metadata(rendered)["splits"]
    assert len(read_steps(out, "all", 3)) == len(read_steps(rendered, "all", 3))


def test_train_sessions_keeps_the_first_train_sessions_only(rendered, tmp_path):
    out = tmp_path / "lab"
    meta = through_camera(rendered, out, 3737, train_sessions=1)
    train = sorted({r["session"] for r in read_records(rendered, "train")})
    assert len(train) >= 2
    for view in ("camera", "inspection"):
        kept = read_records(out, "train", view)
        assert kept and {r["session"] for r in kept} == {train[0]}
        assert all(r.get("source", "human") == "human" for r in kept)
        for split in ("val", "test"):
            assert read_records(out, split, view) == read_records(rendered, split, view)
    assert meta["train_sessions"] == [train[0]]
    assert meta["splits"]["train"] == len(read_records(out, "train"))
    assert sorted(p.name for p in (out / "train" / "color").iterdir()) == sorted(
        r["color"].split("/")[-1] for r in read_records(out, "train"))


@pytest.mark.parametrize("args, words", [
    (["--camera", "1", "--train-sessions", "99"], "--train-sessions 99"),
    (["--camera", "1", "--train-sessions", "0"], "--train-sessions must be >= 1"),
    (["--camera", "-1"], "seed must be"),
])
def test_bad_input_is_one_line_exit_2_and_nothing_written(rendered, tmp_path, capsys, args,
                                                          words):
    before = json.loads((rendered / "dataset.json").read_text())
    assert main([str(rendered), *args, "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and "\n" not in err
    assert list(tmp_path.iterdir()) == []
    assert json.loads((rendered / "dataset.json").read_text()) == before


def test_an_existing_out_folder_is_refused(rendered, tmp_path, capsys):
    (tmp_path / "x").mkdir()
    assert main([str(rendered), "--camera", "1", "--out", str(tmp_path / "x")]) == 2
    assert "exists" in capsys.readouterr().err
    assert list((tmp_path / "x").iterdir()) == []
