"""Sessions without ground truth: perceived, calibrated and learned from like simulated ones.

What a real work cell records is the sensor side alone. These tests strip a simulated session of
its ground truth, and turn one into a plain MP4 video with no depth, then run the pipeline on
them with the shipped models.
"""

from __future__ import annotations

import json
import shutil

import pytest

from onionsort.cli import main
from onionsort.stages.models import CLASSIFIER_FILE, DEFAULT_MODELS, DETECTOR_FILE
from recordings import open_session, strip_ground_truth
from recordings.session.schema import Topic
from recordings.sources.video import write_video

pytestmark = pytest.mark.skipif(
    not (DEFAULT_MODELS / DETECTOR_FILE).exists()
    or not (DEFAULT_MODELS / CLASSIFIER_FILE).exists(),
    reason="the shipped perception models are missing")

STEPS = 8


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """Two recorded sessions and calibrations of the shipped models: RGB-D with the inspection
    view, and colour only without it (what an imported video has)."""
    root = tmp_path_factory.mktemp("sensor_first")
    assert main(["record", "--sessions", "2", "--steps-per-session", str(STEPS),
                 "--occlusion", "0.25", "--seed", "11", "--out", str(root / "rec")]) == 0
    assert main(["dataset", "--frames", "36", "--robot-onions", "0", "--steps-per-session", "4",
                 "--seed", "12", "--out", str(root / "data")]) == 0
    for name, extra in (("cal", []), ("cal_video", ["--no-depth", "--no-inspection"]),
                        ("cal_colour", ["--no-depth"])):
        assert main(["calibrate", "--data", str(root / "data"), "--split", "all",
                     "--out", str(root / name), *extra]) == 0
    return root


def _learn(sessions, calibration, out, *extra) -> dict:
    assert main(["learn", *map(str, sessions), "--observation-model", str(calibration),
                 "--out", str(out), *extra]) == 0
    return json.loads((out / "model.json").read_text())


def test_stripped_sessions_perceive_and_learn_exactly_like_the_originals(work, tmp_path, capsys):
    kept = sorted((work / "rec").glob("*.mcap"))
    originals, stripped = [], []
    for path in kept:
        originals.append(tmp_path / f"gt_{path.name}")
        shutil.copy(path, originals[-1])
        stripped.append(strip_ground_truth(path, tmp_path / f"bare_{path.name}"))
    bare = open_session(stripped[0])
    assert not bare.has_ground_truth and bare.steps == []
    assert all(f.state is None and f.boxes is None for f in bare.frames())
    with pytest.raises(ValueError, match="carries no ground truth"):
        bare.demonstration()
    with stripped[0].open("rb") as fh:
        assert not any(t.encode() in fh.read() for t in Topic.GROUND_TRUTH)

    capsys.readouterr()
    assert main(["perceive", *map(str, originals)]) == 0
    said_gt = capsys.readouterr().out
    assert main(["perceive", *map(str, stripped)]) == 0
    said_bare = capsys.readouterr().out
    counts = [line.split(": ", 1)[1] for line in said_gt.splitlines() if ".mcap:" in line]
    assert counts == [line.split(": ", 1)[1] for line in said_bare.splitlines()
                      if ".mcap:" in line]
    assert all(c.startswith(f"{STEPS} steps") for c in counts)
    for a, b in zip(originals, stripped, strict=True):
        assert open_session(a).perceived_demonstration() == \
            open_session(b).perceived_demonstration()

    with_gt = _learn(originals, work / "cal" / "calibration.json", tmp_path / "learn_gt")
    without = _learn(stripped, work / "cal" / "calibration.json", tmp_path / "learn_bare")
    assert without["policy_indices"] == with_gt["policy_indices"]
    assert without["n_steps"] == with_gt["n_steps"] == 2 * STEPS


def test_a_plain_video_is_imported_perceived_calibrated_colour_only_and_learned_from(
        work, tmp_path, capsys):
    session = open_session(sorted((work / "rec").glob("*.mcap"))[0])
    video = write_video(tmp_path / "line.mp4", (f.color for f in session.frames()),
                        fps=1.5)  # 3 frames per 2-second step, as recorded
    imported = tmp_path / "line.mcap"
    assert main(["import", str(video), "--step-seconds", "2", "--out", str(imported)]) == 0
    got = open_session(imported)
    assert not got.has_ground_truth and not got.has_depth
    assert got.metadata["segmentation"]["method"] == "fixed clock"
    assert [[f.index for f in s] for s in got.step_frames()] == [
        [3 * t, 3 * t + 1, 3 * t + 2] for t in range(STEPS)]
    capsys.readouterr()
    assert main(["perceive", str(imported)]) == 0
    said = capsys.readouterr().out
    assert f"{STEPS} steps" in said and "(colour only)" in said
    record = open_session(imported).perception_models
    assert record["depth"] is False and record["inspection"] is False

    assert main(["learn", str(imported), "--observation-model",
                 str(work / "cal" / "calibration.json"), "--out", str(tmp_path / "bad")]) == 2
    err = capsys.readouterr().err
    assert "perceived without depth and without inspection but" in err
    assert "measured with depth and with inspection" in err
    assert "--no-depth --no-inspection" in err and "calibration-video-no-inspection.json" in err
    doc = json.loads((work / "cal_video" / "calibration.json").read_text())
    doc["inspection"] = True
    (tmp_path / "with_inspection.json").write_text(json.dumps(doc))
    assert main(["learn", str(imported), "--observation-model",
                 str(tmp_path / "with_inspection.json"), "--out", str(tmp_path / "bad2")]) == 2
    assert "measured with inspection" in capsys.readouterr().err
    model = _learn([imported], work / "cal_video" / "calibration.json", tmp_path / "learn")
    assert model["n_steps"] == STEPS and len(model["policy_indices"]) == 48


def test_a_second_video_of_the_inspection_spot_gives_each_step_its_inspection_view(
        work, tmp_path, capsys):
    session = open_session(sorted((work / "rec").glob("*.mcap"))[1])
    frames = list(session.frames())
    views = {f.step: f.inspection for f in frames if f.inspection is not None}
    video = write_video(tmp_path / "line.mp4", (f.color for f in frames), fps=1.5)
    face = write_video(tmp_path / "face.mp4", (views[f.step] for f in frames), fps=1.5)
    imported = tmp_path / "line.mcap"
    assert main(["import", str(video), "--inspection", str(face), "--step-seconds", "2",
                 "--out", str(imported)]) == 0
    got = open_session(imported)
    assert got.has_inspection and not got.has_depth
    steps = got.step_frames()
    assert [s[0].inspection is not None for s in steps] == [True] * STEPS
    assert all(f.inspection is None for s in steps for f in s[1:])
    assert steps[0][0].inspection.shape == views[0].shape
    assert main(["perceive", str(imported)]) == 0
    assert open_session(imported).perception_models["inspection"] is True
    capsys.readouterr()
    assert main(["learn", str(imported), "--observation-model",
                 str(work / "cal_video" / "calibration.json"),
                 "--out", str(tmp_path / "bad")]) == 2
    assert "perceived with inspection but" in capsys.readouterr().err
    model = _learn([imported], work / "cal_colour" / "calibration.json", tmp_path / "learn")
    assert model["n_steps"] == STEPS
    short = write_video(tmp_path / "short.mp4", [views[0]] * 5, fps=1.5)
    assert main(["import", str(video), "--inspection", str(short), "--step-seconds", "2",
                 "--out", str(tmp_path / "x.mcap")]) == 2
    assert "frame for frame" in capsys.readouterr().err
    long = write_video(tmp_path / "long.mp4", [views[0]] * (len(frames) + 2), fps=1.5)
    assert main(["import", str(video), "--inspection", str(long), "--step-seconds", "2",
                 "--out", str(tmp_path / "x.mcap")]) == 2
    assert "more frames than" in capsys.readouterr().err
    assert not (tmp_path / "x.mcap").exists()


def test_learn_refuses_sessions_perceived_by_other_models(work, tmp_path, capsys):
    path = tmp_path / "s.mcap"
    shutil.copy(sorted((work / "rec").glob("*.mcap"))[0], path)
    assert main(["perceive", str(path)]) == 0
    doc = json.loads((work / "cal" / "calibration.json").read_text())
    doc["models"]["detector_sha256"] = "0" * 16
    other = tmp_path / "other.json"
    other.write_text(json.dumps(doc))
    capsys.readouterr()
    assert main(["learn", str(path), "--observation-model", str(other),
                 "--out", str(tmp_path / "refused")]) == 2
    err = capsys.readouterr().err
    assert "perceived by other models" in err and "detector_sha256" in err
    assert "--allow-model-mismatch" in err and not (tmp_path / "refused" / "model.json").exists()
    forced = _learn([path], other, tmp_path / "forced", "--allow-model-mismatch")
    assert "detector_sha256" in forced["model_mismatch_allowed"][0]
    capsys.readouterr()
    assert main(["learn", str(path), "--observation-model", str(other), "--out",
                 str(tmp_path / "forced"), "--allow-model-mismatch"]) == 2
    assert "model.json exists" in capsys.readouterr().err
    _learn([path], other, tmp_path / "forced", "--allow-model-mismatch", "--overwrite")


@pytest.mark.parametrize("case", ["missing", "not a video", "too short", "no camera"])
def test_import_answers_bad_input_with_one_line_and_leaves_no_file(case, tmp_path, capsys):
    out = tmp_path / "s.mcap"
    if case == "missing":
        argv = [str(tmp_path / "nope.mp4")]
    elif case == "not a video":
        (tmp_path / "text.mp4").write_text("not a video")
        argv = [str(tmp_path / "text.mp4")]
    elif case == "too short":
        import numpy as np

        write_video(tmp_path / "short.mp4", [np.zeros((48, 64, 3), np.uint8)] * 2, fps=1.5)
        argv = [str(tmp_path / "short.mp4")]
    else:
        argv = ["--camera", "99"]
    capsys.readouterr()
    assert main(["import", *argv, "--step-seconds", "2", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("onionsort import: error:") and "\n" not in err
    assert sorted(p.name for p in tmp_path.iterdir() if "mcap" in p.name) == []


def test_failed_or_repeated_runs_leave_earlier_results_and_no_empty_folders(work, tmp_path,
                                                                              capsys):
    raw = sorted((work / "rec").glob("*.mcap"))[0]  # never perceived
    assert main(["learn", str(raw), "--observation-model", str(work / "cal" / "calibration.json"),
                 "--out", str(tmp_path / "L")]) == 2
    assert "has no perception topics" in capsys.readouterr().err
    assert not (tmp_path / "L").exists()
    assert main(["calibrate", "--data", str(tmp_path / "nodata"), "--out",
                 str(tmp_path / "C")]) == 2
    assert not (tmp_path / "C").exists()
    before = (work / "cal" / "calibration.json").read_bytes()
    assert main(["calibrate", "--data", str(work / "data"), "--out", str(work / "cal")]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert (work / "cal" / "calibration.json").read_bytes() == before
    session = open_session(raw)
    video = write_video(tmp_path / "v.mp4", (f.color for f in session.frames()), fps=1.5)
    assert main(["import", str(video), "--step-seconds", "100", "--out",
                 str(tmp_path / "s.mcap")]) == 2
    assert "shorter than one step of --step-seconds 100" in capsys.readouterr().err
    assert not (tmp_path / "s.mcap").exists()


def test_perceiving_a_session_reads_each_image_once(work, tmp_path):
    # the inspection's detections of the inspection views are the ones the topic stores
    from onionsort.stages.models import PerceptionModels
    from onionsort.stages.perceive import perceive_session

    path = tmp_path / "session.mcap"
    shutil.copy(sorted((work / "rec").glob("*.mcap"))[0], path)
    models = PerceptionModels.load(device="cpu")
    read = []
    detect = models.detector.detect
    models.detector.detect = lambda images, **kw: read.extend(map(id, images)) or \
        detect(images, **kw)
    perceive_session(models, path, replace=True)
    session = open_session(path)
    n_views = sum(f.inspection_png is not None for f in session.frames())
    assert n_views > 0
    assert len(read) == session.n_frames + n_views  # every frame and every view, once
