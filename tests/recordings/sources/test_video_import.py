"""Importing sessions from a video file or a camera: sources, segmentation, the import itself."""

from __future__ import annotations

import json
import re
import threading

import cv2
import numpy as np
import pytest

from recordings import open_session
from recordings.sources.importer import ImportSummary, import_video
from recordings.sources.segmentation import (
    boundaries_from_labels,
    boundary_scores,
    fixed_clock,
    resample_steps,
    split_long_steps,
    steps_from_boundaries,
)
from recordings.sources.video import (
    CameraNotFoundError,
    CameraSource,
    EmptyVideoError,
    IntrinsicsError,
    SourceError,
    SourceFrame,
    SourceNotFoundError,
    VideoFileSource,
    default_intrinsics,
    load_intrinsics,
)

W, H, FPS = 96, 64, 10.0
#: Flat colours, RGB, distinct enough to survive mp4v compression.
COLOURS = [(200, 30, 30), (30, 200, 30), (30, 30, 200), (200, 200, 30), (30, 200, 200)]


def synthetic_frame(i: int) -> np.ndarray:
    rgb = np.empty((H, W, 3), np.uint8)
    rgb[:] = COLOURS[i % len(COLOURS)]
    return rgb


def write_video(path, n_frames: int, fourcc: str = "mp4v") -> None:
    """A video of ``n_frames`` flat-coloured frames; mp4v/.mp4 works with this OpenCV build
    (avc1/H.264 has no encoder here)."""
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), FPS, (W, H))
    assert writer.isOpened(), f"OpenCV cannot write {fourcc} to {path}"
    for i in range(n_frames):
        writer.write(synthetic_frame(i)[..., ::-1].copy())
    writer.release()


@pytest.fixture(scope="module")
def video(tmp_path_factory):
    path = tmp_path_factory.mktemp("video") / "clip.mp4"
    write_video(path, 20)
    return path


def leftovers(directory):
    return sorted(p.name for p in directory.iterdir()
                  if p.name.endswith(".mcap") or p.name.endswith(".partial"))


# ----------------------------------------------------------------------------- sources


def test_video_file_source_reads_frames(video):
    with VideoFileSource(video) as src:
        assert (src.width, src.height) == (W, H)
        assert src.fps == pytest.approx(FPS)
        assert src.name == str(video)
        frames = list(src)
    assert [f.index for f in frames] == list(range(20))
    times = [f.time_ns for f in frames]
    assert times[0] == 0
    assert np.allclose(np.diff(times), 1e9 / FPS, rtol=1e-3)
    for i, f in enumerate(frames):
        assert f.color.shape == (H, W, 3) and f.color.dtype == np.uint8
        mean = f.color.reshape(-1, 3).mean(axis=0)
        assert np.abs(mean - COLOURS[i % len(COLOURS)]).max() < 20, (i, mean)


def test_source_is_read_once_and_released(video):
    src = VideoFileSource(video)
    assert len(list(src)) == 20
    with pytest.raises(RuntimeError, match="read already"):
        iter(src)
    src.close()
    src.close()  # idempotent


def test_source_frame_validation():
    with pytest.raises(ValueError, match="color"):
        SourceFrame(0, 0, np.zeros((4, 4), np.uint8))
    with pytest.raises(ValueError, match="time_ns"):
        SourceFrame(0, -1, np.zeros((4, 4, 3), np.uint8))


def test_missing_file(tmp_path):
    path = tmp_path / "nope.mp4"
    with pytest.raises(SourceNotFoundError, match=r"nope\.mp4") as info:
        VideoFileSource(path)
    assert isinstance(info.value, FileNotFoundError) and isinstance(info.value, SourceError)
    assert leftovers(tmp_path) == []


def test_text_file_renamed_mp4(tmp_path):
    path = tmp_path / "notes.mp4"
    path.write_text("this is not a video\n")
    with pytest.raises(SourceError, match=r"notes\.mp4.*re-encode"):
        VideoFileSource(path)
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize("name, fourcc, error", [
    ("empty.mp4", "mp4v", SourceError),  # an mp4 without frames has no moov atom: cannot open
    ("empty.avi", "MJPG", EmptyVideoError),  # an avi without frames opens but gives none
])
def test_empty_video(tmp_path, name, fourcc, error):
    path = tmp_path / name
    write_video(path, 0, fourcc)
    with pytest.raises(error, match=re.escape(name)):
        VideoFileSource(path)
    assert leftovers(tmp_path) == []


def test_zero_byte_file(tmp_path):
    path = tmp_path / "zero.mp4"
    path.write_bytes(b"")
    with pytest.raises(SourceError, match=r"zero\.mp4"):
        VideoFileSource(path)
    assert leftovers(tmp_path) == []


def test_no_camera_fails_cleanly_and_quickly():
    outcome = {}

    def attempt():
        try:
            CameraSource(99, max_frames=1)
        except Exception as exc:  # recorded, asserted below
            outcome["error"] = exc

    thread = threading.Thread(target=attempt, daemon=True)
    thread.start()
    thread.join(timeout=20)
    assert not thread.is_alive(), "CameraSource(99) hung"
    assert isinstance(outcome.get("error"), CameraNotFoundError), outcome
    assert "99" in str(outcome["error"])


def test_camera_argument_validation():
    for kwargs in ({"max_frames": 0}, {"max_seconds": 0.0}):
        with pytest.raises(ValueError):
            CameraSource(0, **kwargs)
    with pytest.raises(ValueError, match="index"):
        CameraSource(-1)


# ----------------------------------------------------------------------------- import


def test_import_with_fixed_clock(video, tmp_path):
    out = tmp_path / "imported.mcap"
    with VideoFileSource(video) as src:
        times = [f.time_ns for f in VideoFileSource(video)]
        steps = fixed_clock(times, 0.5)  # 10 fps: 5 frames a step, 4 steps
        summary = import_video(src, out, frames_per_step=3, step_of_frame=steps,
                               camera_K=default_intrinsics(src.width, src.height),
                               metadata={"segmentation": {"mode": "fixed", "step_s": 0.5}})
    assert summary == ImportSummary(path=out, source=str(video), frames_read=20,
                                    frames_written=12, steps_written=4, frames_per_step=3)
    assert leftovers(tmp_path) == ["imported.mcap"]
    session = open_session(out)
    assert session.status == "complete"
    assert session.has_ground_truth is False
    assert session.has_depth is False
    assert session.metadata["source"] == str(video)
    assert session.metadata["segmentation"] == {"mode": "fixed", "step_s": 0.5}
    step_frames = session.step_frames()
    assert len(step_frames) == 4
    assert all(len(s) == 3 for s in step_frames)
    assert [[f.phase for f in s] for s in step_frames] == [[0, 1, 2]] * 4
    # phase k of a 5-frame step is its frame floor(5 k / 3): source frames 0, 1, 3 of each step
    firsts = [s[0] for s in step_frames]
    assert [f.time_ns for f in firsts] == [times[5 * t] for t in range(4)]
    frame = next(session.frames())
    assert frame.depth is None and frame.state is None and frame.inspection is None
    assert np.abs(frame.color.reshape(-1, 3).mean(0) - COLOURS[0]).max() < 20


def test_import_refuses_existing_output(video, tmp_path):
    out = tmp_path / "taken.mcap"
    out.write_bytes(b"keep me")
    with VideoFileSource(video) as src, pytest.raises(FileExistsError, match=r"taken\.mcap"):
        import_video(src, out, frames_per_step=3, step_of_frame=[0] * 20,
                     camera_K=default_intrinsics(W, H))
    assert out.read_bytes() == b"keep me"
    assert leftovers(tmp_path) == ["taken.mcap"]


def test_import_video_shorter_than_a_step(tmp_path):
    path = tmp_path / "short.mp4"
    write_video(path, 2)
    out = tmp_path / "short.mcap"
    with VideoFileSource(path) as src:
        times = [f.time_ns for f in VideoFileSource(path)]
        with pytest.raises(ValueError, match=r"short\.mp4 has 2 frames; a step needs at least 3"):
            import_video(src, out, frames_per_step=3, step_of_frame=fixed_clock(times, 1.0),
                         camera_K=default_intrinsics(W, H))
    assert leftovers(tmp_path) == []


def test_import_failure_removes_partial(video, tmp_path):
    out = tmp_path / "broken.mcap"
    with VideoFileSource(video) as src, pytest.raises(ValueError, match="ended after 20"):
        import_video(src, out, frames_per_step=3, step_of_frame=[0] * 25,
                     camera_K=default_intrinsics(W, H))
    assert leftovers(tmp_path) == []


def test_import_interrupted_removes_partial(tmp_path):
    def frames():
        for i in range(6):
            yield SourceFrame(i, i * 100_000_000, synthetic_frame(i))
        raise KeyboardInterrupt

    out = tmp_path / "stopped.mcap"
    with pytest.raises(KeyboardInterrupt):
        import_video(frames(), out, frames_per_step=3, step_of_frame=[0] * 5 + [1] * 5,
                     camera_K=default_intrinsics(W, H))
    assert leftovers(tmp_path) == []


def test_import_short_steps_repeat_frames(tmp_path):
    frames = [SourceFrame(i, i * 100_000_000, synthetic_frame(i)) for i in range(4)]
    out = tmp_path / "repeats.mcap"
    summary = import_video(frames, out, frames_per_step=3, step_of_frame=[0, 0, 0, 2],
                           camera_K=default_intrinsics(W, H))
    assert (summary.steps_written, summary.frames_written) == (2, 6)
    steps = open_session(out).step_frames()
    assert [[f.time_ns for f in s] for s in steps] == [[0, 1e8, 2e8], [3e8] * 3]


# ----------------------------------------------------------------------------- segmentation


def test_fixed_clock():
    s = 1_000_000_000
    assert fixed_clock([], 1.0) == []
    assert fixed_clock([5 * s, 5 * s + s // 2, 6 * s, 7 * s - 1, 9 * s], 1.0) == [0, 0, 1, 1, 4]
    assert fixed_clock([0, 250_000_000, 500_000_000], 0.25) == [0, 1, 2]
    with pytest.raises(ValueError, match="step_seconds"):
        fixed_clock([0], 0)
    with pytest.raises(ValueError, match="non-decreasing"):
        fixed_clock([2, 1], 1.0)


def test_boundaries_from_labels_debounce():
    assert boundaries_from_labels([], debounce=2) == []
    assert boundaries_from_labels("aaaa", debounce=2) == [0]
    # single-frame flips are flicker
    assert boundaries_from_labels("aabaabaa", debounce=2) == [0]
    assert boundaries_from_labels("aabaabaa", debounce=1) == [0, 2, 3, 5, 6]
    # a change that holds: the boundary is at the first frame of the new run
    assert boundaries_from_labels("aaabbbbcc", debounce=2) == [0, 3, 7]
    assert boundaries_from_labels("aaabbbbcc", debounce=3) == [0, 3]
    # flicker inside the new run restarts its count; back to the old label cancels it
    assert boundaries_from_labels("aabcbbbaa", debounce=3) == [0, 4]
    assert boundaries_from_labels("aabbabbba", debounce=3) == [0, 5]
    # hashable pairs, as perceived (onion, hand) locations
    pairs = [("conv", "home")] * 3 + [("eye", "eye")] + [("conv", "eye")] * 3
    assert boundaries_from_labels(pairs, debounce=2) == [0, 4]
    with pytest.raises(ValueError, match="debounce"):
        boundaries_from_labels("ab", debounce=0)


def test_steps_from_boundaries():
    assert steps_from_boundaries(0, []) == []
    assert steps_from_boundaries(3, []) == [0, 0, 0]
    assert steps_from_boundaries(6, [0, 2, 5]) == [0, 0, 1, 1, 1, 2]
    assert steps_from_boundaries(4, [1]) == [0, 1, 1, 1]
    assert steps_from_boundaries(7, boundaries_from_labels("aabbbcc", debounce=2)) == \
        [0, 0, 1, 1, 1, 2, 2]
    for bad in ([2, 1], [0, 6], [-1]):
        with pytest.raises(ValueError, match="boundaries"):
            steps_from_boundaries(6, bad)


def test_resample_steps():
    assert resample_steps([], 3) == []
    picks = resample_steps([0] * 5 + [1] * 6 + [2] * 1 + [3] * 2, 3)
    assert picks == [[0, 1, 3], [5, 7, 9], [11, 11, 11], [12, 12, 13]]
    assert all(len(p) == 3 for p in picks)
    assert [p[0] for p in picks] == [0, 5, 11, 12]  # first frame of each step
    # empty step numbers (a pause in a fixed clock) are skipped
    assert resample_steps([0, 0, 0, 4, 4, 4], 3) == [[0, 1, 2], [3, 4, 5]]
    assert resample_steps([7, 7], 1) == [[0]]
    with pytest.raises(ValueError, match="non-decreasing"):
        resample_steps([0, 1, 0], 3)
    with pytest.raises(ValueError, match="frames_per_step"):
        resample_steps([0], 0)


def test_boundary_scores():
    exact = boundary_scores([0, 10, 20], [0, 10, 20])
    assert exact == {"precision": 1.0, "recall": 1.0, "f1": 1.0, "n_predicted": 3,
                     "n_true": 3, "n_matched": 3}
    off_by_one = boundary_scores([11], [10], tolerance=1)
    assert (off_by_one["precision"], off_by_one["recall"]) == (1.0, 1.0)
    off_by_two = boundary_scores([12], [10], tolerance=1)
    assert (off_by_two["precision"], off_by_two["recall"], off_by_two["f1"]) == (0.0, 0.0, 0.0)
    # one-to-one: two predictions near one true boundary match it once
    s = boundary_scores([9, 10, 30], [10, 20])
    assert s["n_matched"] == 1
    assert s["precision"] == pytest.approx(1 / 3) and s["recall"] == pytest.approx(1 / 2)
    assert s["f1"] == pytest.approx(2 * (1 / 3) * (1 / 2) / (1 / 3 + 1 / 2))
    # greedy by distance: 11 takes 11 (distance 0), leaving 10 for 9 only within tolerance 1
    s = boundary_scores([9, 11], [10, 11], tolerance=1)
    assert s["n_matched"] == 2
    assert boundary_scores([], [])["f1"] == 1.0
    assert boundary_scores([], [5])["recall"] == 0.0
    assert boundary_scores([5], [], tolerance=0)["precision"] == 0.0


# ----------------------------------------------------------------------------- intrinsics


def test_default_intrinsics():
    K = default_intrinsics(640, 480)
    assert K.shape == (3, 3)
    assert K[0, 0] == pytest.approx(320 / np.tan(np.deg2rad(30)))
    assert K[0, 0] == K[1, 1]
    assert (K[0, 2], K[1, 2]) == (320, 240)
    assert K[2].tolist() == [0, 0, 1]
    with pytest.raises(ValueError, match="hfov_deg"):
        default_intrinsics(640, 480, 180)
    with pytest.raises(ValueError, match="width"):
        default_intrinsics(0, 480)


def test_load_intrinsics(tmp_path):
    K = [[500.0, 0, 320], [0, 510.0, 240], [0, 0, 1]]
    a = tmp_path / "k.json"
    a.write_text(json.dumps({"K": K}))
    assert load_intrinsics(a).tolist() == K
    b = tmp_path / "f.json"
    b.write_text(json.dumps({"fx": 500, "fy": 510, "cx": 320, "cy": 240, "note": "lab"}))
    assert load_intrinsics(b).tolist() == K


@pytest.mark.parametrize("content, match", [
    ("not json", "not JSON"),
    ("[1, 2]", "JSON list"),
    ('{"focal": 3}', "either 'K' or"),
    ('{"K": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "fx": 1}', "not both"),
    ('{"fx": 1, "fy": 1, "cx": 0}', "lacks cy"),
    ('{"fx": "a", "fy": 1, "cx": 0, "cy": 0}', "numbers"),
    ('{"K": [[1, 0], [0, 1]]}', "3x3"),
    ('{"K": [[1, 0, 0], [0, 1, 0], [0, 1, 1]]}', "last row"),
    ('{"K": [[-1, 0, 0], [0, 1, 0], [0, 0, 1]]}', "fx and fy"),
])
def test_load_intrinsics_errors(tmp_path, content, match):
    path = tmp_path / "bad.json"
    path.write_text(content)
    with pytest.raises(IntrinsicsError, match=match) as info:
        load_intrinsics(path)
    assert "bad.json" in str(info.value)


def test_load_intrinsics_missing(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"nope\.json"):
        load_intrinsics(tmp_path / "nope.json")


def test_long_segments_are_cut_into_typical_steps():
    # segments of 3, 3, 9 (three unseen steps), 3 and 7 frames: the median is 3; the 9 frames
    # become 3 steps, the last 7 frames round to 2 steps cut at 18 + 7 // 2
    boundaries = [0, 3, 6, 15, 18]
    assert split_long_steps(boundaries, 25) == [0, 3, 6, 9, 12, 15, 18, 21]
    assert split_long_steps([0, 3], 6) == [0, 3]
    assert split_long_steps([0], 12, typical=4) == [0, 4, 8]
    assert split_long_steps([0], 5, typical=4) == [0]  # 1.25 steps rounds to one
    assert split_long_steps([], 0) == []
    with pytest.raises(ValueError, match="typical must be > 0"):
        split_long_steps([0], 4, typical=0)
