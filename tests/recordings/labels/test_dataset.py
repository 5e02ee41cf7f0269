"""``onionsort dataset``: labelled frames on disk, split by session."""

import json

import numpy as np
import pytest

from irl.domains.onion_sorting import encode_state
from onionsort.cli import main
from onionsort.stages.dataset import split_plan
from recordings.labels.dataset import SPLITS, read_split


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    out = tmp_path_factory.mktemp("ds") / "data"
    code = main(["dataset", "--frames", "14", "--steps-per-session", "2", "--frames-per-step",
                 "2", "--occlusion", "0.5", "--seed", "3", "--robot-onions", "30",
                 "--out", str(out)])
    assert code == 0
    return out


def test_dataset_has_three_disjoint_splits_of_whole_sessions(dataset):
    meta = json.loads((dataset / "dataset.json").read_text())
    assert meta["format"] == "onionsort.dataset/1"
    assert sum(meta["splits"].values()) == 14
    sessions = {}
    for split in SPLITS:
        recs = json.loads((dataset / split / "labels.json").read_text())
        assert len(recs) == meta["splits"][split] > 0
        sessions[split] = {r["session"] for r in recs}
    assert not (sessions["train"] & sessions["val"]) and not (sessions["val"] & sessions["test"])
    assert not (sessions["train"] & sessions["test"])


def test_frames_and_labels_are_consistent(dataset):
    frames = list(read_split(dataset, "train"))
    assert frames
    for f in frames:
        assert f.color.shape == (240, 320, 3) and f.color.dtype == np.uint8
        assert f.depth.shape == (240, 320) and f.depth.dtype == np.float32
        assert np.nanmax(f.depth) < 65.6
        r = f.record
        assert r["state"] == encode_state((r["onion"], r["end_effector"], r["prediction"]))
        assert len(r["boxes"]) == len(r["classes"])
        for (x0, y0, x1, y1), c in zip(r["boxes"], r["classes"], strict=True):
            assert 0 <= x0 < x1 <= 320 and 0 <= y0 < y1 <= 240 and c in (0, 1)
        assert 0.0 <= r["occluded_fraction"] <= 1.0
    assert any(f.record["boxes"] for f in frames)


def test_inspection_views_of_the_sorter_and_of_the_robot_are_labelled(dataset):
    views = [f for split in SPLITS for f in read_split(dataset, split, view="inspection")]
    human = [f for f in views if f.record["source"] == "human"]
    robot = [f for f in views if f.record["source"] == "robot"]
    assert len(robot) == 30 * 8  # 30 onions, each from the robot's 8 inspection poses
    assert sorted({f.record["view"] for f in robot}) == list(range(8))
    for f in robot:
        assert f.color.shape == (240, 320, 3) and f.depth is None  # the robot's own camera
        assert len(f.record["boxes"]) == 1  # the onion in the gripper, seen whole
        x0, y0, x1, y1 = f.record["boxes"][0]
        assert (x1 - x0) * (y1 - y0) > 0.05 * 320 * 240
    assert {f.record["lineup"] for f in read_split(dataset, "test", view="inspection")
            if f.record["source"] == "robot"}
    assert sum(f.record["classes"][0] for f in robot) == 15 * 8  # half of each line-up blemished
    assert len(human) == 14  # every frame: the sorter turns the onion while inspecting it


def test_existing_dataset_is_never_overwritten(dataset, capsys):
    before = (dataset / "dataset.json").read_bytes()
    assert main(["dataset", "--frames", "14", "--steps-per-session", "2",
                 "--frames-per-step", "2", "--out", str(dataset)]) == 2
    assert "already holds a dataset" in capsys.readouterr().err
    assert (dataset / "dataset.json").read_bytes() == before


def test_split_plan():
    assert split_plan(20, 0.15, 0.15) == ["train"] * 14 + ["val"] * 3 + ["test"] * 3
    assert split_plan(3, 0.15, 0.15) == ["train", "val", "test"]
    with pytest.raises(ValueError, match="cannot fill three splits"):
        split_plan(2, 0.15, 0.15)
    with pytest.raises(ValueError, match="--val and --test"):
        split_plan(10, 0.6, 0.5)


def test_read_split_refuses_a_non_dataset(tmp_path):
    with pytest.raises(FileNotFoundError, match="not a dataset folder"):
        list(read_split(tmp_path, "train"))


def test_a_mix_of_levels_gives_each_session_its_level_in_turn(dataset, tmp_path, capsys):
    args = ["dataset", "--frames", "12", "--steps-per-session", "2", "--frames-per-step", "2",
            "--seed", "3", "--robot-onions", "0"]
    assert main([*args, "--difficulty", "clean,hard", "--out", str(tmp_path / "mix")]) == 0
    assert main([*args, "--out", str(tmp_path / "clean")]) == 0
    meta = json.loads((tmp_path / "mix" / "dataset.json").read_text())
    assert meta["session_difficulty"] == ["clean", "hard", "clean"]
    assert [d["name"] for d in meta["config"]["difficulty"]] == ["clean", "hard"]

    def by_session(root):
        out = {}
        for split in SPLITS:
            for f in read_split(root, split):
                out.setdefault(f.record["session"], []).append(f.color)
        return out

    mix, clean = by_session(tmp_path / "mix"), by_session(tmp_path / "clean")
    # a clean session of the mix is the clean dataset's session; the hard one is not
    assert all(np.array_equal(a, b) for a, b in zip(mix[0], clean[0], strict=True))
    assert not any(np.array_equal(a, b) for a, b in zip(mix[1], clean[1], strict=True))
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_:
        main([*args, "--difficulty", "clean,foggy", "--out", str(tmp_path / "bad")])
    assert exit_.value.code == 2
    assert "unknown level 'foggy'" in capsys.readouterr().err
    assert not (tmp_path / "bad").exists()


def test_a_session_read_alone_is_that_session_of_the_whole_read(dataset):
    from recordings.labels.dataset import read_steps, split_sessions

    named = split_sessions(dataset, "all")
    whole = read_steps(dataset, "all", 2)
    alone = [steps for name, k in named for steps in read_steps(dataset, name, 2, session=k)]
    assert len(named) == len({k for _, k in named}) > 2 and len(alone) == len(whole)
    for a, b in zip(alone, whole, strict=True):
        assert [s.record for s in a] == [s.record for s in b]
        for sa, sb in zip(a, b, strict=True):
            assert all(np.array_equal(x, y) for x, y in zip(sa.colors, sb.colors, strict=True))
            assert [v is None for v in sa.views] == [v is None for v in sb.views]
    assert read_steps(dataset, "train", 2, session=10_000) == []
