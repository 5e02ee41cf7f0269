"""The 3D side of sessions: /tf, /joint_states and /scene in Foxglove's schemas, read back with
mcap's CRC-validating reader and checked against the simulator that wrote them."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from recordings import open_session, strip_ground_truth
from recordings.session.rewrite import rewrite_session
from recordings.session.schema import CLASS_COLORS, ROBOT_METADATA, Topic
from recordings.session.urdf import UrdfJoints, rpy_quaternion, viewer_urdf
from recordings.session.world import read_joint_states, read_scene, read_transforms

FPS = 2
SCHEMAS = {Topic.TF: "foxglove.FrameTransforms", Topic.JOINT_STATES: "foxglove.JointStates",
           Topic.SCENE: "foxglove.SceneUpdate"}


def messages(path, topics) -> dict[str, list]:
    """``topic -> [(schema name, sequence, data)]`` read with CRC validation."""
    out: dict[str, list] = {t: [] for t in topics}
    with open(path, "rb") as fh:
        for schema, channel, msg in make_reader(fh, validate_crcs=True).iter_messages(
                topics=list(topics), log_time_order=False):
            out[channel.topic].append((schema.name, msg.sequence, msg.data))
    return out


def mcap_check(path) -> None:
    exe = shutil.which("rerun")
    if exe is None:
        return  # the CLI comes with the SDK; without it only the reading back is checked
    done = subprocess.run([exe, "mcap", "check", str(path)], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "error" not in done.stdout.lower(), done.stdout


def matrix(q) -> np.ndarray:
    """The rotation matrix of quaternion (x, y, z, w)."""
    x, y, z, w = np.asarray(q, float) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


@dataclass
class RobotRun:
    path: object
    q: list[np.ndarray]
    links: list[dict[str, tuple[np.ndarray, np.ndarray]]]  # PyBullet's link frames per frame


def robot_session(path, n_frames: int = 4) -> RobotRun:
    """A short session of the Sawyer moving at its station, with ground truth: each frame's
    world carries the robot, the work cell and the main camera."""
    import pybullet as p

    from irl.demonstrations import StepTruth
    from recordings import SessionWriter
    from robot.assets import sawyer_urdf
    from robot.camera import CameraSpec, intrinsics, render
    from robot.sawyer import HOME, Sawyer
    from robot.scene import StopGate, build_workcell, connect
    from robot.station import ROBOT_BASE, ROBOT_BASE_YAW
    from robot.world import WorldFrame, WorldProbe, WorldState, camera_pose, robot_state

    spec = CameraSpec(width=64, height=48)
    client = connect()
    qs, links = [], []
    try:
        cell = build_workcell(client, np.random.default_rng(0))
        gate = StopGate(client)
        arm = Sawyer(client, base_position=ROBOT_BASE, base_yaw=ROBOT_BASE_YAW)
        probe = WorldProbe(client, {**{f"workcell/{k}": v for k, v in cell.items()},
                                    "gate": gate.body})
        target = HOME + np.array([0.4, 0.3, -0.5, -0.6, 0.3, 0.4, -1.0])
        with SessionWriter(path, {"seed": 0}, intrinsics(spec), frames_per_step=FPS) as writer:
            for k in range(n_frames):
                q = HOME + (target - HOME) * k / (n_frames - 1)
                arm.reset(q)
                qs.append(q)
                links.append({
                    p.getJointInfo(arm.body, j, physicsClientId=client)[12].decode():
                        tuple(np.array(v) for v in p.getLinkState(
                            arm.body, j, computeForwardKinematics=True,
                            physicsClientId=client)[4:6]) for j in arm.joints})
                image = render(client, spec)
                world = WorldState(shapes=probe.shapes(), cameras={"camera": camera_pose(spec)},
                                   robot=robot_state(client, arm.body, arm.joints,
                                                     sawyer_urdf()))
                writer.write_frame(WorldFrame(
                    index=k, step=StepTruth(k // FPS, 0, 0, 0, False), phase=k % FPS,
                    time_s=0.1 * k, color=image.rgb, depth=image.depth, world=world))
    finally:
        p.disconnect(client)
    return RobotRun(path, qs, links)


@pytest.fixture(scope="module")
def robot_run(tmp_path_factory) -> RobotRun:
    return robot_session(tmp_path_factory.mktemp("robot") / "robot.mcap")


def test_a_recorded_session_places_its_cameras_and_onions(recorded):
    got = messages(recorded.path, [Topic.TF, Topic.SCENE, Topic.JOINT_STATES, Topic.ONIONS,
                                   Topic.BOXES])
    n = len(recorded.frames)
    assert [s for s, _, _ in got[Topic.TF]] == [SCHEMAS[Topic.TF]] * n
    assert [s for s, _, _ in got[Topic.SCENE]] == [SCHEMAS[Topic.SCENE]] * n
    assert got[Topic.JOINT_STATES] == []  # a sorter's world has no robot
    K = np.array(open_session(recorded.path).metadata["camera_K"])
    boxes = {seq: data for _, seq, data in got[Topic.BOXES]}
    projected = 0
    for _, seq, data in got[Topic.TF]:
        tf = read_transforms(data)
        assert {f: tf[f][0] for f in ("camera", "inspection")} == {"camera": "world",
                                                                  "inspection": "world"}
        _, t, q = tf["camera"]
        frame = recorded.frames[seq]
        for box in json.loads(boxes[seq])["boxes"]:
            if box["visible_pixels"] < 150:
                continue  # a sliver at the edge of the view: its box centre is not the onion's
            onion = next(o for o in frame.onions if o.onion_id == box["onion_id"])
            x = matrix(q).T @ (onion.position - t)  # world -> optical frame (x right, y down)
            u, v = (K @ x / x[2])[:2]
            assert abs(u - (box["x_min"] + box["x_max"]) / 2) < 6, (seq, box)
            assert abs(v - (box["y_min"] + box["y_max"]) / 2) < 6, (seq, box)
            projected += 1
    assert projected > n  # the camera pose was checked against many onions
    for _, seq, data in got[Topic.SCENE]:
        items = {item.name: item for item in read_scene(data)}
        assert {"workcell/belt", "gate", "sorter/hand", "passer_by/coat"} <= set(items)
        for onion in recorded.frames[seq].onions:
            item = items[f"onions/{onion.onion_id}"]
            assert item.class_id == int(onion.blemished)
            np.testing.assert_allclose(item.rgba[:3] * 255, CLASS_COLORS[item.class_id],
                                       atol=1e-3)
            np.testing.assert_allclose(item.position, onion.position, atol=1e-6)
    mcap_check(recorded.path)


def test_a_robot_session_has_joint_states_and_link_transforms(robot_run):
    path = robot_run.path
    got = messages(path, list(SCHEMAS))
    for topic, schema in SCHEMAS.items():
        assert [s for s, _, _ in got[topic]] == [schema] * len(robot_run.q), topic
    kin = UrdfJoints(viewer_urdf(open_session(path).robot["urdf"]))
    for (_, _, js), (_, _, tf), q, links in zip(got[Topic.JOINT_STATES], got[Topic.TF],
                                                 robot_run.q, robot_run.links, strict=True):
        joints = read_joint_states(js)
        assert list(joints) == [f"right_j{k}" for k in range(7)]
        np.testing.assert_allclose(list(joints.values()), q, atol=1e-9)
        tf = read_transforms(tf)
        assert tf["camera"][0] == "world" and tf[kin.root][0] == "world"
        # compose the tree from the world and compare every link with PyBullet's frames
        poses = {"world": (np.zeros(3), np.eye(3))}
        pending = dict(tf)
        while pending:
            child = next(c for c, (parent, _, _) in pending.items() if parent in poses)
            parent, t, r = pending.pop(child)
            pt, pr = poses[parent]
            poses[child] = (pt + pr @ t, pr @ matrix(r))
        for link, (pos, orn) in links.items():
            np.testing.assert_allclose(poses[link][0], pos, atol=1e-6)
            np.testing.assert_allclose(poses[link][1], matrix(orn), atol=1e-6)
    session = open_session(path)
    assert session.robot["root_link"] == "right_arm_base_link"
    assert session.robot["joints"] == [f"right_j{k}" for k in range(7)]
    frame = next(session.frames())
    assert frame.joints is not None and frame.scene is not None
    assert {item.name for item in frame.scene} >= {"workcell/belt", "workcell/bin_floor", "gate"}
    with open(path, "rb") as fh:
        names = [m.name for m in make_reader(fh, validate_crcs=True).iter_metadata()]
    assert names.count(ROBOT_METADATA) == 1
    mcap_check(path)


def test_stripping_ground_truth_keeps_tf_and_drops_the_scene(robot_run, tmp_path):
    out = strip_ground_truth(robot_run.path, tmp_path / "sensor.mcap")
    got = messages(out, list(SCHEMAS))
    assert got[Topic.SCENE] == []
    assert len(got[Topic.TF]) == len(got[Topic.JOINT_STATES]) == len(robot_run.q)
    frame = next(open_session(out).frames())
    assert frame.scene is None and frame.transforms is not None and frame.joints is not None


def test_sessions_without_the_3d_topics_still_open(recorded, tmp_path):
    old = rewrite_session(recorded.path, tmp_path / "old.mcap",
                          drop_topics=(Topic.TF, Topic.SCENE, Topic.JOINT_STATES))
    assert messages(old, list(SCHEMAS)) == {t: [] for t in SCHEMAS}
    session = open_session(old)
    assert session.robot is None and session.n_frames == len(recorded.frames)
    assert all(f.transforms is None and f.scene is None and f.joints is None
               for f in session.frames())
    np.testing.assert_array_equal(session.trajectory().states, [s.state for s in recorded.steps])


def test_urdf_transforms_follow_the_urdf(tmp_path):
    urdf = tmp_path / "arm.urdf"
    urdf.write_text("""<robot name="arm">
      <link name="base"/><link name="upper"/><link name="slide"/>
      <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
        <origin xyz="0 0 1" rpy="0 0 1.5707963267948966"/><axis xyz="0 1 0"/></joint>
      <joint name="rail" type="prismatic"><parent link="upper"/><child link="slide"/>
        <origin xyz="0 0 0.5"/><axis xyz="1 0 0"/></joint>
    </robot>""")
    kin = UrdfJoints(urdf)
    assert (kin.name, kin.root, kin.moving) == ("arm", "base", ("shoulder", "rail"))
    shoulder, rail = kin.transforms({"shoulder": np.pi / 2, "rail": 0.2})
    np.testing.assert_allclose(shoulder.translation, [0, 0, 1])
    # yaw 90 degrees, then 90 degrees about the (yawed) y axis: x_child = world -z ... as a
    # matrix product Rz(90) Ry(90)
    rz = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    ry = np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]])
    np.testing.assert_allclose(matrix(shoulder.rotation), rz @ ry, atol=1e-12)
    np.testing.assert_allclose(rail.translation, [0.2, 0, 0.5])
    np.testing.assert_allclose(matrix(rpy_quaternion([0.3, -0.2, 0.1])),
                               matrix(rpy_quaternion([0, 0, 0.1]))
                               @ matrix(rpy_quaternion([0, -0.2, 0]))
                               @ matrix(rpy_quaternion([0.3, 0, 0])), atol=1e-12)
    with pytest.raises(ValueError, match="no joints named"):
        kin.transforms({"elbow": 1.0})
    (tmp_path / "two.urdf").write_text('<robot name="x"><link name="a"/><link name="b"/></robot>')
    with pytest.raises(ValueError, match="exactly one root"):
        UrdfJoints(tmp_path / "two.urdf")


def test_viewer_urdf_resolves_packages_and_swaps_collada(tmp_path):
    pkg = tmp_path / "src" / "arm_description"
    (pkg / "meshes").mkdir(parents=True)
    (pkg / "urdf").mkdir()
    (pkg / "package.xml").write_text("<package><name>arm_description</name></package>")
    for name in ("a.dae", "a.stl", "b.dae"):
        (pkg / "meshes" / name).write_bytes(b"mesh")
    urdf = pkg / "urdf" / "arm.urdf"
    urdf.write_text("""<robot name="arm"><link name="a">
      <visual><geometry><mesh filename="package://arm_description/meshes/a.dae"/></geometry>
      </visual><collision><geometry><box size="1 1 1"/></geometry></collision></link>
      <link name="b"><visual><geometry>
        <mesh filename="package://arm_description/meshes/b.dae"/></geometry></visual></link>
      <joint name="j" type="fixed"><parent link="a"/><child link="b"/></joint></robot>""")
    out = viewer_urdf(urdf, cache=tmp_path / "cache")
    text = out.read_text()
    assert f'filename="{pkg / "meshes" / "a.stl"}"' in text  # the .stl beside the .dae
    assert f'filename="{pkg / "meshes" / "b.dae"}"' in text  # no .stl to swap in: kept
    assert "package://" not in text and "<collision" not in text
    assert urdf.read_text().count("package://") == 2  # the original is untouched
    assert viewer_urdf(urdf, cache=tmp_path / "cache") == out
    urdf.write_text(urdf.read_text().replace("meshes/b.dae", "meshes/missing.stl"))
    with pytest.raises(FileNotFoundError, match=r"missing\.stl"):
        viewer_urdf(urdf, cache=tmp_path / "cache")


def test_the_sawyers_viewer_urdf_uses_only_stl_meshes():
    from robot.assets import sawyer_urdf

    text = viewer_urdf(sawyer_urdf()).read_text()
    meshes = re.findall(r'filename="([^"]+)"', text)
    assert len(meshes) == 8 and all(m.endswith(".stl") for m in meshes)
    assert all(Path(m).is_file() for m in meshes)


def test_camera_pose_is_the_optical_frame():
    from robot.camera import CameraSpec, intrinsics
    from robot.world import Pose, camera_pose

    spec = CameraSpec(eye=(1.0, -2.0, 1.5), target=(1.0, 0.0, 1.5))  # looking along +y
    pose = camera_pose(spec)
    np.testing.assert_allclose(pose.position, spec.eye)
    np.testing.assert_allclose(matrix(pose.orientation),
                               [[1, 0, 0], [0, 0, 1], [0, -1, 0]], atol=1e-12)
    # a point straight ahead projects to the principal point, one above it to a lower v
    K = intrinsics(spec)
    for point, expect in (([1.0, 1.0, 1.5], (160, 120)), ([1.0, 1.0, 1.6], None)):
        x = matrix(pose.orientation).T @ (np.array(point) - pose.position)
        u, v = (K @ x / x[2])[:2]
        if expect:
            np.testing.assert_allclose((u, v), expect, atol=1e-9)
        else:
            assert v < 120 and abs(u - 160) < 1e-9
    with pytest.raises(ValueError, match="parallel"):
        camera_pose(CameraSpec(eye=(0, 0, 2.0), target=(0, 0, 0.0)))
    with pytest.raises(ValueError, match="non-zero quaternion"):
        Pose([0, 0, 0], [0, 0, 0, 0])
