"""``onionsort export --format ros2``: a session as a rosbag2 folder, read back with rosbags'
own reader (``rosbags.highlevel.AnyReader``), never with ours, and compared with the session."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from onionsort.cli import main
from recordings import SessionWriter, open_session
from recordings.session.schema import Topic
from recordings.sources.ros_export import ROBOT_TOPIC, SESSION_TOPIC, STORAGES, export_ros2
from tests.recordings.session.test_evaluation_session import Decision
from tests.recordings.session.test_world import robot_session

COMPRESSED = "sensor_msgs/msg/CompressedImage"
IMAGE = "sensor_msgs/msg/Image"
INFO = "sensor_msgs/msg/CameraInfo"
STRING = "std_msgs/msg/String"


@dataclass
class Bag:
    """A rosbag2 folder read back: each topic's type, and its ``(log time, message)``s."""

    types: dict[str, str]
    messages: dict[str, list[tuple[int, object]]]

    def counts(self) -> dict[str, tuple[str, int]]:
        return {t: (self.types[t], len(self.messages[t])) for t in self.types}

    def json(self, topic: str) -> list:
        return [json.loads(m.data) for _, m in self.messages[topic]]


def read_bag(path: Path) -> Bag:
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    with AnyReader([Path(path)], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        messages: dict[str, list] = {t: [] for t in types}
        for conn, time_ns, raw in reader.messages():
            messages[conn.topic].append((time_ns, reader.deserialize(raw, conn.msgtype)))
    return Bag(types, messages)


def stamp_ns(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


@pytest.fixture(scope="module")
def exported(recorded, tmp_path_factory):
    out = tmp_path_factory.mktemp("export") / "bag"
    summary = export_ros2(recorded.path, out)
    return summary, read_bag(out), open_session(recorded.path)


def test_the_bag_has_the_expected_topics_types_and_counts(exported):
    summary, bag, session = exported
    n, n_steps = session.n_frames, len(session.steps)
    n_views = sum(f.inspection_png is not None for f in session.frames())
    assert session.has_depth and session.has_inspection and session.has_ground_truth
    assert bag.counts() == {
        SESSION_TOPIC: (STRING, 1),
        Topic.COLOR: (COMPRESSED, n), Topic.DEPTH: (IMAGE, n), "/camera/camera_info": (INFO, n),
        Topic.INSPECTION: (COMPRESSED, n_views), "/inspection/camera_info": (INFO, n_views),
        Topic.TF: ("tf2_msgs/msg/TFMessage", n), Topic.STEP_CLOCK: (STRING, n),
        Topic.STATE: (STRING, n), Topic.ACTION: (STRING, n_steps), Topic.BOXES: (STRING, n),
        Topic.ONIONS: (STRING, n),
    }
    assert summary.topics == bag.counts() and summary.n_frames == n
    assert summary.skipped == (Topic.ANNOTATIONS, Topic.SCENE)
    assert sorted(p.name for p in summary.path.iterdir()) == ["bag.mcap", "metadata.yaml"]
    assert not summary.path.with_name("bag.partial").exists()


def test_images_and_depth_are_the_sessions_bytes_at_the_sessions_times(exported):
    _, bag, session = exported
    frames = list(session.frames())
    times = [f.time_ns for f in frames]
    for topic in (Topic.COLOR, Topic.DEPTH, "/camera/camera_info", Topic.TF, Topic.STEP_CLOCK):
        assert [t for t, _ in bag.messages[topic]] == times, topic
    for f, (_, color), (_, depth) in zip(frames, bag.messages[Topic.COLOR],
                                         bag.messages[Topic.DEPTH], strict=True):
        assert color.format == "jpeg" and color.header.frame_id == "camera"
        assert color.data.tobytes() == f.color_jpeg and stamp_ns(color) == f.time_ns
        h, w = f.depth_shape
        assert (depth.encoding, depth.height, depth.width, depth.step, depth.is_bigendian) == (
            "16UC1", h, w, 2 * w, 0)
        assert depth.data.tobytes() == f.depth_raw and stamp_ns(depth) == f.time_ns
        mm = np.frombuffer(depth.data.tobytes(), "<u2").reshape(h, w)
        assert np.array_equal(mm, np.round(f.depth.astype(float) * 1000.0))
    views = [f for f in frames if f.inspection_png is not None]
    for f, (t, view) in zip(views, bag.messages[Topic.INSPECTION], strict=True):
        assert (view.format, view.header.frame_id, t) == ("png", "inspection", f.time_ns)
        assert view.data.tobytes() == f.inspection_png


def test_camera_info_holds_the_sessions_intrinsics(exported):
    _, bag, session = exported
    first = next(session.frames())
    for topic, key, image, frame_id in (
            ("/camera/camera_info", "camera_K", first.color, "camera"),
            ("/inspection/camera_info", "inspection_K", first.inspection, "inspection")):
        K = np.asarray(session.metadata[key], float)
        for _, info in bag.messages[topic]:
            assert np.allclose(info.k, K.ravel()), topic
            assert np.allclose(info.p, np.hstack([K, np.zeros((3, 1))]).ravel())
            assert np.array_equal(info.r, np.eye(3).ravel()) and np.array_equal(info.d, np.zeros(5))
            assert (info.height, info.width) == image.shape[:2]
            assert (info.distortion_model, info.header.frame_id) == ("plumb_bob", frame_id)


def test_the_step_clock_session_record_tf_and_ground_truth_match_the_session(exported):
    _, bag, session = exported
    frames = list(session.frames())
    assert bag.json(Topic.STEP_CLOCK) == [
        {"frame": f.index, "step": f.step, "phase": f.phase} for f in frames]
    assert bag.json(SESSION_TOPIC) == [json.loads(json.dumps(session.metadata))]
    assert bag.messages[SESSION_TOPIC][0][0] == frames[0].time_ns
    assert bag.json(Topic.STATE) == [f.state for f in frames]
    assert [(m["step"], m["state"], m["action"], m["next_state"], m["occluded"])
            for m in bag.json(Topic.ACTION)] == [
        (s.step, s.state, s.action, s.next_state, s.occluded) for s in session.steps]
    for f, (_, tf) in zip(frames, bag.messages[Topic.TF], strict=True):
        got = {t.child_frame_id: (t.header.frame_id, t.transform.translation,
                                  t.transform.rotation) for t in tf.transforms}
        assert set(got) == set(f.transforms) >= {"camera", "inspection"}
        for child, (parent, xyz, q) in f.transforms.items():
            assert got[child][0] == parent
            assert np.allclose([got[child][1].x, got[child][1].y, got[child][1].z], xyz)
            assert np.allclose([got[child][2].x, got[child][2].y, got[child][2].z,
                                got[child][2].w], q)


@pytest.mark.parametrize("storage", sorted(STORAGES))
def test_raw_images_in_either_storage_read_back(storage, recorded, tmp_path):
    summary = export_ros2(recorded.path, tmp_path / "raw", raw_images=True, storage=storage)
    suffix = {"mcap": ".mcap", "sqlite3": ".db3"}[storage]
    assert sorted(p.suffix for p in summary.path.iterdir()) == sorted([suffix, ".yaml"])
    bag = read_bag(summary.path)
    session = open_session(recorded.path)
    assert bag.types[Topic.COLOR] == bag.types[Topic.INSPECTION] == IMAGE
    assert bag.counts() == summary.topics
    for f, (_, img) in zip(session.frames(), bag.messages[Topic.COLOR], strict=True):
        h, w = f.color.shape[:2]
        assert (img.encoding, img.height, img.width, img.step, img.is_bigendian) == (
            "rgb8", h, w, 3 * w, 0)
        assert np.array_equal(img.data.reshape(h, w, 3), f.color)
    views = [f for f in session.frames() if f.inspection_png is not None]
    _, img = bag.messages[Topic.INSPECTION][0]
    assert np.array_equal(img.data.reshape(img.height, img.width, 3), views[0].inspection)


def test_a_sensor_only_session_without_depth_keeps_its_evaluation_topics(tmp_path):
    K = np.array([[40.0, 0.0, 16.0], [0.0, 40.0, 12.0], [0.0, 0.0, 1.0]])
    path = tmp_path / "s.mcap"
    rng = np.random.default_rng(0)
    with SessionWriter(path, {"seed": 0}, K, frames_per_step=2, depth=False,
                       ground_truth=False) as writer:
        for i in range(4):
            if i % 2 == 0:
                writer.write_decision(Decision(step=i // 2), frame=i, time_ns=i * 10**8)
            writer.write_sensor_frame(index=i, step=i // 2, phase=i % 2, time_ns=i * 10**8,
                                      color=rng.integers(0, 256, (24, 32, 3), dtype=np.uint8))
    summary = export_ros2(path, tmp_path / "bag")
    bag = read_bag(summary.path)
    assert set(bag.types) == {SESSION_TOPIC, Topic.COLOR, "/camera/camera_info",
                              Topic.STEP_CLOCK, Topic.DECISION}
    assert summary.skipped == ()
    decisions = open_session(path).decisions
    assert bag.json(Topic.DECISION) == [decisions[0], decisions[1]]
    assert [t for t, _ in bag.messages[Topic.DECISION]] == [0, 2 * 10**8]
    assert np.allclose(bag.messages["/camera/camera_info"][0][1].k, K.ravel())


def test_a_robot_session_has_joint_states_and_link_transforms(tmp_path):
    run = robot_session(tmp_path / "robot.mcap")
    session = open_session(run.path)
    bag = read_bag(export_ros2(run.path, tmp_path / "bag").path)
    assert bag.counts()[Topic.JOINT_STATES] == ("sensor_msgs/msg/JointState", len(run.q))
    for q, f, (_, js), (_, tf) in zip(run.q, session.frames(), bag.messages[Topic.JOINT_STATES],
                                      bag.messages[Topic.TF], strict=True):
        assert list(js.name) == [f"right_j{k}" for k in range(7)]
        assert np.allclose(js.position, q) and stamp_ns(js) == f.time_ns
        children = {t.child_frame_id: t.header.frame_id for t in tf.transforms}
        assert children["right_arm_base_link"] == "world" and {f"right_l{k}" for k in
                                                                range(7)} <= set(children)
    assert bag.json(ROBOT_TOPIC) == [json.loads(json.dumps(session.robot))]


def test_the_cli_exports_once_and_refuses_an_existing_out(recorded, tmp_path, capsys):
    out = tmp_path / "bag"
    assert main(["export", str(recorded.path), "--format", "ros2", "--out", str(out)]) == 0
    assert "exported" in capsys.readouterr().out
    before = sorted((p.name, p.stat().st_mtime_ns) for p in out.iterdir())
    assert main(["export", str(recorded.path), "--format", "ros2", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "exists" in err
    assert sorted((p.name, p.stat().st_mtime_ns) for p in out.iterdir()) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bag"]
    with pytest.raises(FileExistsError, match="exists"):
        export_ros2(recorded.path, out)


@pytest.mark.parametrize("what", ["not mcap", "truncated", "missing"])
def test_bad_input_is_one_line_and_exit_2_and_writes_nothing(what, recorded, tmp_path, capsys):
    src = tmp_path / "in.mcap"
    if what == "not mcap":
        src.write_text("no session here\n")
    elif what == "truncated":
        data = Path(recorded.path).read_bytes()
        src.write_bytes(data[: len(data) // 2])
    out = tmp_path / "bag"
    assert main(["export", str(src), "--format", "ros2", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("onionsort export: error:"), err
    assert {"not mcap": "not an MCAP file", "truncated": "truncated or corrupt",
            "missing": "no such recording"}[what] in err
    assert not out.exists() and not out.with_name("bag.partial").exists()


def test_a_failure_while_writing_removes_the_partial_folder(recorded, tmp_path, monkeypatch):
    from recordings.sources import ros_export

    def broken(*args, **kwargs):
        raise RuntimeError("disk on fire")

    monkeypatch.setattr(ros_export._Bag, "tf", broken)
    with pytest.raises(RuntimeError, match="disk on fire"):
        export_ros2(recorded.path, tmp_path / "bag")
    assert list(tmp_path.iterdir()) == []


def test_a_stale_partial_folder_is_replaced(recorded, tmp_path):
    stale = tmp_path / "bag.partial"
    (stale / "bag").mkdir(parents=True)
    (stale / "bag" / "junk").write_text("from a killed export")
    summary = export_ros2(recorded.path, tmp_path / "bag")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bag"]
    assert "junk" not in {p.name for p in summary.path.iterdir()}


def test_the_config_refuses_bad_values_and_the_parser_lists_the_storages(tmp_path):
    from onionsort.stages import ExportConfig
    from onionsort.stages.export import ROS2_STORAGES

    assert tuple(STORAGES) == ROS2_STORAGES
    with pytest.raises(ValueError, match="format must be one of ros2; got 'ros1'"):
        ExportConfig(session=tmp_path / "s.mcap", out=tmp_path / "bag", format="ros1")
    with pytest.raises(ValueError, match="storage must be one of mcap, sqlite3"):
        ExportConfig(session=tmp_path / "s.mcap", out=tmp_path / "bag", storage="db3")
    with pytest.raises(FileExistsError):
        ExportConfig(session=tmp_path / "s.mcap", out=tmp_path)
    with pytest.raises(ValueError, match="storage must be one of"):
        export_ros2(tmp_path / "s.mcap", tmp_path / "bag", storage="zip")
