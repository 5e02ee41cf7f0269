"""``bench/finetune_camera.py``: the pieces of the fine-tuning measurement that run fast (the
measurement itself renders and trains for half an hour: docs/lab.md gives its command)."""

import pytest

from bench.finetune_camera import _first_test_sessions, _recovered, _sessions_for_views, main
from onionsort.cli import main as onionsort
from recordings.labels.dataset import read_records, read_steps


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """6 sessions of 4 steps of 3 frames: 2 train, 1 val, 3 test."""
    out = tmp_path_factory.mktemp("ft") / "data"
    assert onionsort(["dataset", "--frames", "72", "--steps-per-session", "4",
                      "--robot-onions", "0", "--seed", "7", "--val", "0.17", "--test", "0.5",
                      "--workers", "1", "--out", str(out)]) == 0
    return out


def test_the_share_recovered_is_of_the_drop_and_none_without_one():
    assert _recovered(0.9, 0.8, 0.85) == pytest.approx(0.5)
    assert _recovered(0.9, 0.8, 0.75) == pytest.approx(-0.5)  # worse than not fine-tuning
    assert _recovered(0.9, 0.92, 0.95) is None  # the camera cost nothing
    assert _recovered(0.9, 0.9, 0.95) is None


def test_the_test_split_cut_to_its_first_sessions_links_the_images(rendered, tmp_path):
    test = sorted({r["session"] for r in read_records(rendered, "test")})
    assert len(test) >= 2
    out = _first_test_sessions(rendered, tmp_path / "cut", 1)
    assert {r["session"] for r in read_records(out, "test")} == {test[0]}
    assert {r["session"] for r in read_records(out, "test", "inspection")} == {test[0]}
    for split in ("train", "val"):
        assert read_records(out, split) == read_records(rendered, split)
    steps = read_steps(out, "test", 3)
    assert len(steps) == 1 and steps[0][0].colors[0].shape == (240, 320, 3)
    assert _first_test_sessions(rendered, tmp_path / "none", None) == rendered


def test_the_lab_is_the_fewest_train_sessions_that_hold_the_views(rendered):
    per = {s: 0 for s in {r["session"] for r in read_records(rendered, "train")}}
    for r in read_records(rendered, "train", "inspection"):
        if r.get("boxes"):
            per[r["session"]] = per.get(r["session"], 0) + 1
    counts = [per[s] for s in sorted(per)]
    assert len(counts) == 2 and sum(counts) > 0
    # the first K sessions in through_camera's order, sessions without a view counted
    for target in range(1, sum(counts) + 1):
        assert _sessions_for_views(rendered, target) == min(
            k for k in range(1, len(counts) + 1) if sum(counts[:k]) >= target)
    with pytest.raises(ValueError, match="fewer than --views"):
        _sessions_for_views(rendered, sum(per.values()) + 1)


def test_an_existing_out_is_one_line_exit_2(rendered, tmp_path, capsys):
    (tmp_path / "out").mkdir()
    assert main(["--models", str(rendered), "--data", str(rendered), "--mix", str(rendered),
                 "--cameras", "1", "--out", str(tmp_path / "out")]) == 2
    (err,) = capsys.readouterr().err.splitlines()
    assert err == f"finetune_camera: error: {tmp_path / 'out'} exists; give a new folder"
