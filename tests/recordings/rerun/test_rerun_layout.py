"""What a person sees in Rerun: each kind of recording (session, perceived session, learning,
evaluation; the demo's in tests/test_demo.py) opens on views that all have data, and 3D views
that hold nothing they cannot place (no 2D entity outside a pinhole, no series, no text).

The blueprints are read back from tiny ``.rrd`` files (:mod:`tests.recordings.rerun.rrd_layout`).
"""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from onionsort.stages.learn_rerun import log_learning
from recordings import open_session
from recordings.rerun import SessionLogger
from recordings.session.perception import add_perception
from tests.recordings.rerun.rrd_layout import blueprint_views, entities, layout_problems, matches
from tests.recordings.rerun.test_rerun import sensor_session, verify
from tests.recordings.session.test_world import robot_session

pytest.importorskip("rerun.chunk")


@pytest.fixture(scope="module")
def sessions(recorded, tmp_path_factory):
    """A simulated session (depth, inspection, ground truth; the recordings tests' shared one)
    and a camera-only one."""
    return open_session(recorded.path), sensor_session(tmp_path_factory.mktemp("layout") /
                                                       "sensor.mcap")


@pytest.fixture(scope="module")
def robot_run(tmp_path_factory):
    return robot_session(tmp_path_factory.mktemp("robot") / "robot.mcap")


def test_query_expressions_follow_rerun_rules():
    # the example of Rerun's entity-query reference
    rules = ("+ /world/**", "- /world", "- /world/car/**", "+ /world/car/driver")
    assert matches("world/car/driver", "", rules)
    assert not matches("world/car/hood", "", rules)
    assert not matches("world", "", rules)
    assert matches("world/house", "", rules)
    assert not matches("elsewhere", "", rules)
    camera = ("$origin/**", "- $origin/depth")
    assert matches("record/camera/color", "record/camera", camera)
    assert matches("record/camera", "record/camera", camera)
    assert not matches("record/camera/depth", "record/camera", camera)
    assert not matches("record/camera_2", "record/camera", camera)


def _perceived(session, path, inspection: bool):
    """A copy of ``session`` at ``path`` with perception topics: one perceived step per step,
    the second called occluded, a box on every frame (and on the inspection views)."""
    shutil.copy(session.path, path)
    frames = list(session.frames())
    first = {}
    for f in frames:
        first.setdefault(f.step, f)
    docs = [{"step": t, "frame": f.index, "occluded": t == 1,
             "p_occluded": 0.9 if t == 1 else 0.1, "onion": 1, "end_effector": 1, "action": 0,
             "prediction": 2, "state": 11, "observation": None if t == 1 else 55,
             "inspected": None, "probs": {}} for t, f in sorted(first.items())]
    views = {f.index: [(2, 2, 12, 12, 1, 0.8)] for f in frames if f.inspection_png is not None}
    add_perception(path, docs, detections={f.index: [(1, 2, 10, 12, 1, 0.9)] for f in frames},
                   inspection=views if inspection else {},
                   frame_times={f.index: f.time_ns for f in frames}, models={"test": True})
    return open_session(path)


def _log(out, *sessions):
    with SessionLogger(out) as log:
        for i, session in enumerate(sessions):
            log.log_session(session, i)
    return out


def assert_layout(path) -> None:
    assert layout_problems(path) == []
    verify(path)


def test_session_recordings(sessions, robot_run, tmp_path):
    sim, sensor = sessions
    out = _log(tmp_path / "sim.rrd", sim)
    assert_layout(out)
    views = {v.name: v for v in blueprint_views(out)}
    assert {"camera + ground-truth boxes", "work cell (3D)", "depth", "inspection",
            "true state", "occlusion"} <= set(views)
    assert not any(v.origin.startswith("perceive") for v in views.values())  # not perceived
    assert views["work cell (3D)"].hidden == {"record/camera/depth"}  # under the bodies
    # the inspection camera is a pinhole placed in 3D, with its image in its frustum
    assert matches("record/inspection", "record", views["work cell (3D)"].contents)
    assert not matches("record/truth/state", "record", views["work cell (3D)"].contents)

    out = _log(tmp_path / "robot.rrd", open_session(robot_run.path))
    assert_layout(out)
    assert matches("record/robot/joints/right_j0", "record",
                   next(v for v in blueprint_views(out) if v.kind == "3D").contents)

    out = _log(tmp_path / "sensor.rrd", sensor)  # colour only: no depth, truth, inspection
    assert_layout(out)
    assert {v.name for v in blueprint_views(out)} == {"camera", "work cell (3D)", "session"}


def test_perceived_session_recordings(sessions, tmp_path):
    sim, sensor = sessions
    out = _log(tmp_path / "perceived.rrd", _perceived(sim, tmp_path / "sim.mcap",
                                                      inspection=True))
    assert_layout(out)
    names = {v.name for v in blueprint_views(out)}
    assert {"perceived step", "inspection detections", "observations", "perceived factors",
            "occlusion calls"} <= names
    # without an inspection view perception has none to show
    out = _log(tmp_path / "sensor.rrd", _perceived(sensor, tmp_path / "sensor.mcap",
                                                   inspection=False))
    assert_layout(out)
    names = {v.name for v in blueprint_views(out)}
    assert "perceived step" in names and "inspection detections" not in names
    # a perceived session after one that was not: the layout grows to show it
    out = _log(tmp_path / "both.rrd", sensor, _perceived(sensor, tmp_path / "again.mcap",
                                                         inspection=False))
    assert_layout(out)
    assert "observations" in {v.name for v in blueprint_views(out)}


def test_learning_recordings(tmp_path):
    model = {"theta": {"good_on_line": 1.5, "bad_in_bin": -0.5},
             "policy": [{"state": "s0", "action": "pick"}, {"state": "s1", "action": "claim"}]}
    out = tmp_path / "learn.rrd"
    log_learning(out, model, [{"log_likelihood": -10.0 + k} for k in range(5)])
    assert_layout(out)
    assert {v.name for v in blueprint_views(out)} == {"objective", "reward weights", "policy"}
    confidence = {"states": [
        {"state": "s0", "description": "first", "map_action": "pick",
         "confidence": {"pick": 0.9, "claim": 0.1}},
        {"state": "s1", "description": "second", "map_action": "claim",
         "confidence": {"pick": 0.4, "claim": 0.6}}]}
    out = tmp_path / "posterior.rrd"
    log_learning(out, model, [], confidence=confidence)  # no objective recorded
    assert_layout(out)
    assert {v.name for v in blueprint_views(out)} == {
        "reward weights", "policy", "confidence per state", "least sure states"}


@pytest.fixture(scope="module")
def evaluation(tmp_path_factory):
    """``onionsort evaluate --policy expert`` on a line-up of two onions, three views each
    (every view taken), with the shipped models; its session beside it."""
    from onionsort.cli import main

    out = tmp_path_factory.mktemp("evaluate") / "eval"
    assert main(["evaluate", "--policy", "expert", "--onions", "2", "--blemished", "1",
                 "--inspection-views", "3", "--every-view", "--device", "cpu",
                 "--out", str(out)]) == 0
    return out / "evaluation.rrd"


def test_evaluation_recording(evaluation):
    assert_layout(evaluation)
    views = {v.name: v for v in blueprint_views(evaluation)}
    held = entities(evaluation)
    world = views["Sawyer station (3D)"]
    # the inspection camera is a pinhole at its station: the first view shows in its frustum
    assert "Pinhole" in held["evaluate/inspection"]
    assert "Transform3D" in held["evaluate/inspection"]
    assert matches("evaluate/inspection/view_0", "evaluate", world.contents)
    assert not matches("evaluate/inspection/view_1", "evaluate", world.contents)
    assert not matches("evaluate/inspection/p_blemished", "evaluate", world.contents)
    # a view per inspection view that was used, and only those
    used = {e for e in held if e.startswith("evaluate/inspection/view_") and "/" not in
            e.removeprefix("evaluate/inspection/") and "Image" in held[e]}
    assert {v.origin for v in views.values() if v.name.startswith("view ")} == used


def test_each_inspection_view_shows_its_own_call_and_the_fused_call_beside(evaluation):
    """On every onion, each inspection view's box has the class of that view's own call (its
    P(blemished), as the session recorded it, against the evaluation's threshold), not the
    detector's; the fused call logged beside the views is the robot's decision."""
    import json

    from tests.recordings.rerun.test_rerun import logged_boxes, logged_verdicts

    saved = json.loads((evaluation.parent / "evaluation.json").read_text())
    threshold = saved["threshold"]
    inspected = [d for d in open_session(evaluation.with_suffix(".mcap")).decisions.values()
                 if d.get("view_p_blemished")]
    assert sorted(d["onion"] for d in inspected) == [o["index"] for o in saved["onions"]]
    boxes, verdicts = logged_boxes(evaluation), logged_verdicts(evaluation)
    calls = {"good": 0, "bad": 1, None: None}
    wrong, labels, views_seen = [], [], 0
    for decision in inspected:
        step = decision["step"]
        for k, p in enumerate(decision["view_p_blemished"]):
            logged, views_seen = boxes[step, k], views_seen + 1
            if p is None:  # the inspection found no onion to read: no class drawn
                want = []
            elif abs(p - threshold) > 1e-5:  # the session rounds to 5 decimals
                want = [int(p >= threshold)]
                labels.append((logged["labels"], [f"{('good', 'blemished')[want[0]]}: "
                                                  f"P(blemished) {p:.2f}"]))
            else:
                continue
            if logged["class_ids"] != want:
                wrong.append((step, k, p, logged["class_ids"], logged["labels"]))
    assert views_seen >= 2 * 3 and wrong == []  # (step, view, P, class_ids, labels)
    assert all(got == want for got, want in labels), labels
    for decision in inspected:
        step, call = decision["step"], calls[decision["perceived"]]
        assert verdicts[step]["call"] == call, (step, decision, verdicts[step])
        name = {0: "fused call good", 1: "fused call blemished", None: "no call"}[call]
        assert name in verdicts[step]["text"]
        if decision["p_blemished"] is not None:
            assert f"P(blemished) {decision['p_blemished']:.2f}" in verdicts[step]["text"]
    assert set(verdicts) == {d["step"] for d in inspected}
    views = {v.name: v for v in blueprint_views(evaluation)}
    assert views["fused call"].origin == "evaluate/inspection/verdict"


def test_depth_beyond_the_work_cell_is_left_out(evaluation):
    """The depth cloud keeps the work cell (belt, robot within 3 m of the camera) and drops
    the floor and far plane beyond; in 3D it starts hidden under the bodies and the robot."""
    import rerun.chunk as rr_chunk

    from recordings.rerun.common import WORK_CELL_DEPTH_M

    depths = []
    for chunk in rr_chunk.RrdReader(evaluation).store().stream():
        if chunk.entity_path.strip("/") == "evaluate/camera/depth":
            batch = chunk.to_record_batch()
            if "DepthImage:buffer" in batch.schema.names:
                for buffer in batch.column("DepthImage:buffer").to_pylist():
                    depths.append(np.frombuffer(bytes(buffer[0]), np.float32))
    assert depths
    depth = np.concatenate(depths)
    kept = depth[depth > 0]
    assert kept.size > 0.3 * depth.size  # the work cell is most of the picture
    assert kept.max() <= WORK_CELL_DEPTH_M
    assert (depth == 0).any()  # the far plane was in view and is gone
    world = next(v for v in blueprint_views(evaluation) if v.kind == "3D")
    assert world.hidden == {"evaluate/camera/depth"}


def test_evaluation_without_views_or_pinholes_keeps_2d_out_of_3d(tmp_path):
    """An evaluation logged without intrinsics: its images stay in 2D views only."""
    from onionsort.stages.evaluate_rerun import EvaluationLogger
    from tests.recordings.rerun.test_rerun import FakeStep

    out = tmp_path / "bare.rrd"
    with EvaluationLogger(out, views=3) as log:
        for t in range(3):
            log.on_step(FakeStep(step=t, state=11, action=t, next_state=17,
                                 color=np.zeros((24, 32, 3), np.uint8),
                                 inspection=np.zeros((12, 16, 3), np.uint8) if t == 1 else None))
    assert_layout(out)
    kinds = {v.name: v.kind for v in blueprint_views(out)}
    assert "Sawyer station (3D)" not in kinds  # nothing 3D to show
    assert {"Sawyer station", "view 0", "decisions"} <= set(kinds)
    assert "view 1" not in kinds and "depth" not in kinds


def test_the_check_flags_the_layout_that_issue_41_reported(tmp_path):
    """The check itself can fail: the evaluation layout as it was (a 3D view of everything
    under the root, 2D inspection views without a pinhole, a view of an entity never logged)
    and a second blueprint are each reported."""
    import rerun as rr
    import rerun.blueprint as rrb

    from recordings.rerun.common import close_recording, open_recording, send_layout

    old = rrb.Blueprint(rrb.Horizontal(
        rrb.Spatial3DView(origin="evaluate", contents=["$origin/**"], name="3D"),
        rrb.Spatial2DView(origin="evaluate/inspection/view_0", name="view 0"),
        rrb.TimeSeriesView(origin="evaluate/inspection/p_blemished", name="P(blemished)")))
    out = tmp_path / "old.rrd"
    rec = open_recording("layout_check", out, old)
    rec.set_time("step", sequence=0)
    rec.log("evaluate/inspection/view_0", rr.Image(np.zeros((4, 6, 3), np.uint8)))
    rec.log("evaluate/scene/belt", rr.Boxes3D(half_sizes=[[1.0, 0.2, 0.05]]))
    close_recording(rec)
    problems = layout_problems(out)
    assert any("3D view '3D' holds /evaluate/inspection/view_0" in p for p in problems)
    assert any("view 'P(blemished)'" in p and "shows no data" in p for p in problems)
    assert not any("'view 0'" in p for p in problems)  # a 2D view of a 2D image is fine

    twice = tmp_path / "twice.rrd"
    rec = open_recording("layout_check", twice, rrb.Blueprint(
        rrb.Spatial2DView(origin="evaluate/inspection/view_0", name="view 0")))
    rec.log("evaluate/inspection/view_0", rr.Image(np.zeros((4, 6, 3), np.uint8)))
    send_layout(rec, rrb.Blueprint(rrb.Spatial2DView(origin="evaluate/inspection/view_0",
                                                     name="view 0")))
    close_recording(rec)
    assert any("2 blueprints" in p for p in layout_problems(twice))
