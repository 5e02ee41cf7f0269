"""The Rerun loggers of ``recordings.rerun``: what each writes, read back from its .rrd file."""

from __future__ import annotations

import json
import logging
import shutil
import subprocess
from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np
import pytest

from onionsort.stages.evaluate_rerun import EvaluationLogger
from onionsort.stages.learn_rerun import log_learning
from recordings import SessionWriter, open_session
from recordings.rerun import SessionLogger, open_recording
from recordings.session.perception import add_perception
from recordings.session.rewrite import rewrite_session
from recordings.session.schema import ROBOT_METADATA
from recordings.session.urdf import UrdfJoints, viewer_urdf
from tests.recordings.session.test_world import matrix, robot_session

rr_chunk = pytest.importorskip("rerun.chunk")
SAWYER_LINKS = {"right_arm_base_link", *(f"right_l{k}" for k in range(7))}
SAWYER_JOINTS = [f"right_j{k}" for k in range(7)]

K = np.array([[100.0, 0.0, 16.0], [0.0, 100.0, 12.0], [0.0, 0.0, 1.0]])
FPS = 2


def summary(path) -> dict[str, dict]:
    """Per entity path (no leading slash): temporal rows and chunks, static rows, whether any
    data is static, timelines, columns."""
    out: dict[str, dict] = defaultdict(lambda: {"rows": 0, "chunks": 0, "static_rows": 0,
                                                "static": set(), "timelines": set(),
                                                "cols": set()})
    for chunk in rr_chunk.RrdReader(path).store().stream():
        e = out[chunk.entity_path.lstrip("/") or "/"]
        if chunk.is_static:
            e["static_rows"] += chunk.num_rows
        else:
            e["rows"] += chunk.num_rows
            e["chunks"] += 1
        e["static"].add(chunk.is_static)
        e["timelines"].update(chunk.timeline_names)
        e["cols"].update(chunk.to_record_batch().schema.names)
    return dict(out)


def views(path, kind: str = "3D") -> list[str]:
    """The origins of the blueprint's views of class ``kind``."""
    reader = rr_chunk.RrdReader(path)
    out = []
    for chunk in reader.store(store=reader.blueprints()[0]).stream():
        batch = chunk.to_record_batch()
        if "ViewBlueprint:class_identifier" in batch.schema.names:
            for cls, origin in zip(batch.column("ViewBlueprint:class_identifier").to_pylist(),
                                   batch.column("ViewBlueprint:space_origin").to_pylist(),
                                   strict=True):
                if cls == [kind]:
                    out.extend(origin)
    return out


def rows(path, entity: str, column: str, timeline: str) -> list[tuple]:
    """``(time, value)`` of every row of ``entity`` that has ``column``, by time."""
    out = []
    for chunk in rr_chunk.RrdReader(path).store().stream():
        if chunk.entity_path.lstrip("/") != entity:
            continue
        batch = chunk.to_record_batch()
        if column in batch.schema.names and timeline in batch.schema.names:
            out += zip(batch.column(timeline).to_pylist(), batch.column(column).to_pylist(),
                       strict=True)
    return sorted(out, key=lambda r: r[0])


def assert_sawyer(s: dict, root: str, n: int) -> None:
    """The Sawyer's 8 visual meshes (static, one Asset3D each, no collision geometry) and a
    transform of each of its 7 joints at ``n`` times under ``root``."""
    meshes = {e.split("/")[4] for e in s if e.startswith(f"{root}/robot/sawyer/visual_geometries/")
              and any(c.startswith("Asset3D:blob") for c in s[e]["cols"])}
    assert meshes == SAWYER_LINKS
    assert all(s[e]["static"] == {True} for e in s if e.startswith(f"{root}/robot/sawyer/"))
    assert not any("collision" in e for e in s)
    for name in SAWYER_JOINTS:
        e = s[f"{root}/robot/joints/{name}"]
        assert e["rows"] == n, name
        assert {"Transform3D:parent_frame", "Transform3D:child_frame",
                "Transform3D:quaternion"} <= e["cols"], name


def assert_series(s: dict, entity: str, n: int) -> None:
    """``entity`` holds ``n`` rows sent in one send_columns call, and its static name."""
    assert s[entity]["rows"] == n, entity
    assert s[entity]["chunks"] == 1, entity
    assert s[entity]["static_rows"] == 1, entity  # the SeriesLines name


def verify(path) -> None:
    exe = shutil.which("rerun")
    if exe is None:
        return  # the CLI comes with the SDK; without it only the reading back is checked
    done = subprocess.run([exe, "rrd", "verify", str(path)], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0, done.stderr


def simulated_session(path, n_steps=5):
    """A short simulated session with depth and ground truth."""
    from robot.camera import intrinsics
    from robot.simulation import SessionConfig, SortingSession, expert_model

    policy, initial = expert_model()
    config = SessionConfig(n_steps=n_steps, occlusion=0.3, frames_per_step=FPS)
    with SortingSession(config, policy, initial, 4) as sim, SessionWriter(
        path, {"seed": 4, "config": config.to_dict()}, intrinsics(config.camera),
        intrinsics(config.inspection), frames_per_step=FPS,
    ) as writer:
        for frame in sim.frames():
            writer.write_frame(frame)
    return open_session(path)


def sensor_session(path, n_steps=3):
    """A camera-only session: colour and the step clock, no depth, no ground truth."""
    rng = np.random.default_rng(0)
    with SessionWriter(path, {"source": "test"}, K, None, frames_per_step=FPS,
                       ground_truth=False, depth=False) as writer:
        for i in range(n_steps * FPS):
            writer.write_sensor_frame(index=i, step=i // FPS, phase=i % FPS,
                                      time_ns=i * 50_000_000,
                                      color=rng.integers(0, 255, (24, 32, 3), np.uint8))
    return open_session(path)


@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    folder = tmp_path_factory.mktemp("rerun")
    return simulated_session(folder / "sim.mcap"), sensor_session(folder / "sensor.mcap")


def test_open_recording_refuses_unknown_targets(tmp_path):
    for target in (tmp_path / "out.txt", "http://localhost:9876", "viewer"):
        with pytest.raises(ValueError, match="target must be"):
            open_recording("test", target)
    with pytest.raises(ValueError, match="application_id"):
        open_recording("", tmp_path / "x.rrd")


def test_rgbd_session_with_ground_truth(sessions, tmp_path):
    sim, _ = sessions
    out = tmp_path / "sim.rrd"
    with SessionLogger(out) as log:
        log.log_session(sim, 0)
    s = summary(out)
    assert {"record/camera", "record/camera/color", "record/camera/depth",
            "record/camera/color/truth_boxes", "record/truth/state",
            "record/inspection"} <= set(s)
    assert s["record/camera"]["static_rows"] == 1  # the pinhole; /tf places it in time
    assert s["/"]["static"] == {True} and any("AnnotationContext" in c for c in s["/"]["cols"])
    assert s["record/camera/color"]["rows"] == sim.n_frames
    assert s["record/camera/color"]["timelines"] >= {"frame", "step", "time"}
    for name in ("onion", "end_effector", "prediction", "action"):
        assert_series(s, f"record/truth/factors/{name}", len(sim.steps))
    assert_series(s, "record/truth/occlusion/fraction", len(sim.steps))
    assert s["record/truth/factors/onion"]["timelines"] >= {"frame", "step", "time"}
    assert not any(e.startswith("perceive") for e in s)
    assert len(rr_chunk.RrdReader(out).blueprints()) == 1
    # the work cell in 3D: one view at the world root, the cameras placed by /tf (fixed: one
    # row each), the static bodies logged once, the moving ones as they move
    assert views(out) == ["record"]
    assert s["record"]["static"] == {True}  # view coordinates: z up
    for camera in ("record/camera", "record/inspection"):
        assert "Transform3D:translation" in s[camera]["cols"]
        assert any(c.startswith("Pinhole:") for c in s[camera]["cols"])
    assert len(rows(out, "record/camera", "Transform3D:translation", "frame")) == 1
    assert s["record/scene/workcell/boxes"]["rows"] == 1
    onions = rows(out, "record/scene/onions/spheres", "Ellipsoids3D:class_ids", "frame")
    assert 1 < len(onions) <= sim.n_frames
    truth = {f.index: {o["onion_id"]: int(o["blemished"]) for o in f.onions}
             for f in sim.frames()}
    for frame, class_ids in onions:
        assert sorted(class_ids) == sorted(truth[frame].values())
    assert {"record/scene/sorter/capsules", "record/scene/gate/boxes",
            "record/scene/passer_by/boxes"} <= set(s)
    assert not any(e.startswith("record/robot") for e in s)  # a sorter's session
    verify(out)


@pytest.fixture(scope="module")
def robot_run(tmp_path_factory):
    return robot_session(tmp_path_factory.mktemp("robot") / "robot.mcap")


def test_robot_session_in_3d(robot_run, tmp_path):
    run = robot_run
    out = tmp_path / "robot.rrd"
    with SessionLogger(out) as log:
        log.log_session(open_session(run.path), 0)
    s = summary(out)
    assert_sawyer(s, "record", len(run.q))
    assert s["record/robot/joints/right_j0"]["timelines"] >= {"frame", "step", "time"}
    assert s["record/robot/base"]["rows"] == 1  # the base stands still
    # Rerun's joint transforms (UrdfJoint.compute_transform) equal the URDF's own, which the
    # MCAP test checks against PyBullet
    from robot.assets import sawyer_urdf

    kin = UrdfJoints(viewer_urdf(sawyer_urdf()))
    for k, name in enumerate(SAWYER_JOINTS):
        logged = rows(out, f"record/robot/joints/{name}", "Transform3D:quaternion", "frame")
        assert [frame for frame, _ in logged] == list(range(len(run.q)))
        for (_, quat), q in zip(logged, run.q, strict=True):
            want = kin.transforms(dict(zip(SAWYER_JOINTS, q, strict=True)))[k]
            np.testing.assert_allclose(matrix(quat[0]), matrix(want.rotation), atol=1e-5)
    assert views(out) == ["record"]
    verify(out)


def test_a_robot_whose_urdf_is_gone_is_left_out_of_3d(robot_run, tmp_path, caplog):
    path = tmp_path / "moved.mcap"
    record = dict(open_session(robot_run.path).robot, urdf=str(tmp_path / "gone.urdf"))
    record["joints"] = json.dumps(record["joints"])
    rewrite_session(robot_run.path, path, drop_metadata=(ROBOT_METADATA,),
                    add=lambda writer: {ROBOT_METADATA: record})
    out = tmp_path / "moved.rrd"
    with caplog.at_level(logging.WARNING), SessionLogger(out) as log:
        log.log_session(open_session(path), 0)
    assert "gone.urdf" in caplog.text and "left out of the 3D view" in caplog.text
    s = summary(out)
    assert not any(e.startswith("record/robot") for e in s)
    assert s["record/camera/color"]["rows"] == len(robot_run.q)  # the rest is logged
    assert "record/scene/workcell/boxes" in s
    verify(out)


def test_sensor_only_session_has_no_ground_truth_entities(sessions, tmp_path):
    _, sensor = sessions
    out = tmp_path / "sensor.rrd"
    with SessionLogger(out) as log:
        log.log_session(sensor, 0)
        log.log_session(sensor, 1)  # steps and frames count on across sessions
    s = summary(out)
    assert s["record/camera/color"]["rows"] == 2 * sensor.n_frames
    assert "record/camera" in s
    assert not any(e.startswith(("record/truth/state", "record/camera/depth",
                                 "record/camera/color/truth_boxes", "record/inspection"))
                   for e in s)
    assert all(s[e]["rows"] == 0 for e in s if e.startswith("record/truth/"))  # names only
    verify(out)


def test_perceived_session_is_logged_under_perceive(sessions, tmp_path):
    _, sensor = sessions
    path = tmp_path / "perceived.mcap"
    shutil.copy(sensor.path, path)
    frames = list(sensor.frames())
    steps = sorted({f.step for f in frames})
    docs = [{"step": t, "frame": t * FPS, "occluded": t == 1, "p_occluded": 0.9 if t == 1
             else 0.1, "onion": 1, "end_effector": 1, "action": 0, "prediction": 2,
             "state": 11, "observation": None if t == 1 else 55, "inspected": None,
             "probs": {}} for t in steps]
    add_perception(path, docs, detections={f.index: [(1, 2, 10, 12, 1, 0.9)] for f in frames},
                   inspection={}, frame_times={f.index: f.time_ns for f in frames},
                   models={"test": True})
    perceived = open_session(path)
    out = tmp_path / "perceived.rrd"
    with SessionLogger(out) as log:
        log.log_session(perceived, 0)
    s = summary(out)
    for name in ("onion", "end_effector", "prediction", "action"):
        assert_series(s, f"perceive/factors/{name}", len(steps))
    assert_series(s, "perceive/occlusion/p_occluded", len(steps))
    assert s["perceive/observation"]["rows"] == len(steps)
    assert s["perceive/camera/color/detections"]["rows"] == len(steps)
    verify(out)


def test_learning(tmp_path):
    out = tmp_path / "learn.rrd"
    model = {"theta": {"good_on_line": 1.5, "bad_in_bin": -0.5},
             "policy": [{"state": "s0", "action": "pick"}]}
    log_learning(out, model, [{"log_likelihood": -10.0 + k} for k in range(7)])
    s = summary(out)
    assert_series(s, "learn/objective", 7)
    assert "iteration" in s["learn/objective"]["timelines"]
    assert s["learn/theta"]["static"] == {True} and s["learn/policy"]["static"] == {True}
    verify(out)
    with pytest.raises(ValueError, match="theta"):
        log_learning(tmp_path / "bad.rrd", {"policy": []}, [])


@dataclass(frozen=True)
class FakeStep:
    step: int
    state: int
    action: int
    next_state: int
    onion: int | None = 0
    blemished: bool | None = True
    perceived: int | None = None
    fate: str | None = None
    tp: int = 0
    fp: int = 0
    tn: int = 0
    fn: int = 0
    color: np.ndarray | None = field(default=None, repr=False)
    depth: np.ndarray | None = field(default=None, repr=False)
    inspection: np.ndarray | None = field(default=None, repr=False)
    q: np.ndarray = field(default_factory=lambda: np.zeros(7), repr=False)
    world: object = field(default=None, repr=False)
    views: tuple = field(default=(), repr=False)
    p_blemished: float | None = None
    view_p_blemished: tuple = ()

    @property
    def precision(self) -> float:
        return self.tp / (self.tp + self.fp) if self.tp + self.fp else 0.0

    @property
    def recall(self) -> float:
        return self.tp / (self.tp + self.fn) if self.tp + self.fn else 0.0


@dataclass
class FakeDetection:
    boxes: np.ndarray
    classes: np.ndarray
    scores: np.ndarray


def test_evaluation(tmp_path):
    out = tmp_path / "eval.rrd"
    calls = []

    def detect(images):
        calls.append(len(images))
        return [FakeDetection(np.array([[1.0, 1.0, 5.0, 6.0]]), np.array([1]),
                              np.array([0.8])) for _ in images]

    from robot.assets import sawyer_urdf
    from robot.camera import CameraSpec
    from robot.station import ROBOT_BASE
    from robot.world import Pose, RobotState, ShapeState, WorldState, camera_pose

    sawyer = RobotState(name="sawyer", urdf=sawyer_urdf(), base=Pose(ROBOT_BASE, [0, 0, 0, 1]),
                        joint_names=tuple(SAWYER_JOINTS), positions=np.zeros(7))
    pose = Pose([0, 0, 0], [0, 0, 0, 1])
    world = WorldState(shapes=(
        ShapeState("workcell/belt", "box", np.array([3.0, 0.3, 0.04]), np.array([0.2] * 4), pose),
        ShapeState("onions/0", "sphere", np.full(3, 0.07), np.ones(4), pose, class_id=1),
    ), cameras={"camera": camera_pose(CameraSpec())})
    n = 6
    with EvaluationLogger(out, detector=detect, camera_K=K, robot=sawyer,
                          camera_pose=camera_pose(CameraSpec())) as log:
        for t in range(n):
            log.on_step(FakeStep(
                step=t, state=11, action=t % 5, next_state=17, perceived=0 if t == 2 else None,
                fate="bin" if t == 3 else None, tp=t // 2, fp=t // 3,
                color=np.zeros((24, 32, 3), np.uint8), depth=np.ones((24, 32), np.float32),
                inspection=np.zeros((12, 16, 3), np.uint8) if t == 2 else None,
                q=np.full(7, 0.1 * t), world=world))
    assert calls == [1]
    s = summary(out)
    assert_sawyer(s, "evaluate", n)
    assert s["evaluate/robot/base"]["static"] == {True}
    assert s["evaluate/camera"]["static"] == {True}
    assert "Transform3D:translation" in s["evaluate/camera"]["cols"]
    assert s["evaluate/scene/onions/spheres"]["rows"] == 1
    assert views(out) == ["evaluate"]
    joints = rows(out, "evaluate/robot/joints/right_j3", "Transform3D:quaternion", "step")
    assert [t for t, _ in joints] == list(range(n))
    assert not np.allclose(joints[0][1], joints[-1][1])  # the arm moved
    for entity in ("metrics/precision", "metrics/recall", "counts/tp", "counts/fn",
                   "mdp/state", "mdp/action", "arm/joints"):
        assert_series(s, f"evaluate/{entity}", n)
    assert {"evaluate/camera", "evaluate/camera/color", "evaluate/camera/depth",
            "evaluate/inspection/view_0", "evaluate/inspection/view_0/detections"} <= set(s)
    assert s["evaluate/decisions"]["rows"] == n
    assert s["/"]["static"] == {True}
    verify(out)


def logged_boxes(path, root: str = "evaluate") -> dict[tuple[int, int], dict]:
    """The inspection boxes each step logged, by ``(step, view)``: each ``Boxes2D`` column
    (``class_ids``, ``labels``, ``colors``, ``centers``) as that row wrote it (None: not
    written)."""
    out = {}
    prefix = f"{root}/inspection/view_"
    for chunk in rr_chunk.RrdReader(path).store().stream():
        entity = chunk.entity_path.strip("/")
        if not (entity.startswith(prefix) and entity.endswith("/detections")):
            continue
        k = int(entity.removeprefix(prefix).split("/")[0])
        batch = chunk.to_record_batch()
        names = [n for n in batch.schema.names if n.startswith("Boxes2D:")]
        for i, step in enumerate(batch.column("step").to_pylist()):
            out[(step, k)] = {n.removeprefix("Boxes2D:"): batch.column(n)[i].as_py()
                              for n in names}
    return out


def logged_verdicts(path, root: str = "evaluate") -> dict[int, dict]:
    """The fused call each inspecting step logged, by step: ``text`` (the verdict beside the
    views) and ``call`` (the scalar: 1 blemished, 0 good; None where none was logged)."""
    out: dict[int, dict] = defaultdict(lambda: {"text": None, "call": None})
    for step, text in rows(path, f"{root}/inspection/verdict", "TextDocument:text", "step"):
        out[step]["text"] = text[0]
    for step, call in rows(path, f"{root}/inspection/call", "Scalars:scalars", "step"):
        out[step]["call"] = call[0]
    return dict(out)


def test_each_inspection_view_shows_its_own_call_and_the_fused_call_stands_beside(tmp_path):
    """The box of a view is the one the inspection read, its class the view's own call at the
    robot's threshold (never the detector's class), its label the view's probability; a view
    with no call shows the detector's boxes grey and classless; the fused call and its
    probability are logged beside the views at each inspection."""
    out = tmp_path / "verdicts.rrd"

    def detect(images):  # every view: the onion as "blemished" 0.8 and as "good" 0.3
        return [FakeDetection(np.array([[1.0, 1.0, 9.0, 9.0], [1.5, 1.0, 9.0, 9.5]]),
                              np.array([1, 0]), np.array([0.8, 0.3])) for _ in images]

    image = np.zeros((12, 16, 3), np.uint8)
    with EvaluationLogger(out, detector=detect, views=3, threshold=0.35) as log:
        log.on_step(FakeStep(step=0, state=11, action=1, next_state=17, onion=4,
                             blemished=False, perceived=0, views=(image,) * 3,
                             p_blemished=0.2, view_p_blemished=(0.1, 0.4, None)))
        log.on_step(FakeStep(step=1, state=17, action=2, next_state=11, onion=4,
                             blemished=False, fate="line"))
        log.on_step(FakeStep(step=2, state=11, action=1, next_state=18, onion=5, perceived=1,
                             views=(image,) * 2, p_blemished=0.9, view_p_blemished=(0.3, 0.2)))
        log.on_step(FakeStep(step=3, state=11, action=1, next_state=17, onion=6,
                             perceived=None, views=(image,), view_p_blemished=(None,)))
    boxes = logged_boxes(out)
    assert set(boxes) == {(0, 0), (0, 1), (0, 2), (2, 0), (2, 1), (3, 0)}
    # against the threshold given, 0.35: 0.1 good, 0.4 blemished (the detector said
    # blemished for both); one box each, the one read
    assert [boxes[0, k]["class_ids"] for k in (0, 1)] == [[0], [1]]
    assert [boxes[0, k]["labels"] for k in (0, 1)] == [["good: P(blemished) 0.10"],
                                                       ["blemished: P(blemished) 0.40"]]
    assert boxes[0, 0]["centers"] == [[5.0, 5.0]]
    assert boxes[0, 0]["colors"] == [0x28C83CFF]  # the colour of class good, (40, 200, 60)
    # no call in view 2: both boxes, grey, no class
    assert boxes[0, 2]["class_ids"] == [] and len(boxes[0, 2]["colors"]) == 2
    assert boxes[0, 2]["labels"] == ["not read: onion 0.80", "not read: onion 0.30"]
    assert [boxes[2, k]["class_ids"] for k in (0, 1)] == [[0], [0]]
    assert boxes[3, 0]["class_ids"] == []  # nothing of step 0's class stays
    verdicts = logged_verdicts(out)
    assert set(verdicts) == {0, 2, 3}
    assert [verdicts[t]["call"] for t in (0, 2, 3)] == [0.0, 1.0, None]
    assert verdicts[0]["text"].startswith("**onion 4: fused call good**, P(blemished) 0.20 "
                                          "(threshold 0.35)")
    assert "- view 1: blemished, P(blemished) 0.40" in verdicts[0]["text"]
    assert "- view 2: no onion found" in verdicts[0]["text"]
    assert verdicts[2]["text"].startswith("**onion 5: fused call blemished**, P(blemished) 0.90")
    assert verdicts[3]["text"].startswith("**onion 6: no call**")
    verify(out)
    with pytest.raises(ValueError, match="threshold must be in"):
        EvaluationLogger(tmp_path / "bad.rrd", threshold=1.0)
