"""`onionsort import BAG`: ROS 2 (MCAP, sqlite3) and ROS 1 bags written by a third party's writer
(``rosbags``, not ours) from a recorded session's frames come back as that session's steps and
frames."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore

from onionsort.cli import main
from onionsort.stages import ImportConfig, import_video, list_bag
from recordings import open_session
from recordings.sources.bags import BagError, is_bag

ROS2, ROS1 = get_typestore(Stores.ROS2_HUMBLE), get_typestore(Stores.ROS1_NOETIC)
IMAGE, COMPRESSED = "sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage"
INFO, STRING = "sensor_msgs/msg/CameraInfo", "std_msgs/msg/String"
COLOR_ENCODINGS = ("rgb8", "bgr8", "mono8", "jpeg", "png")


class BagOut:
    """A bag written with rosbags' own writers: ROS 2 MCAP or sqlite3, or ROS 1."""

    def __init__(self, path: Path, storage: str):
        self.ros1 = storage == "ros1"
        self.store = ROS1 if self.ros1 else ROS2
        self.path = path.with_suffix(".bag") if self.ros1 else path
        self.writer = (Writer1(self.path) if self.ros1 else Writer2(
            self.path, version=9, storage_plugin=StoragePlugin[storage.upper()]))
        self.connections: dict[str, object] = {}

    def __enter__(self):
        self.writer.open()
        return self

    def __exit__(self, *exc):
        self.writer.close()

    def header(self, t: int, frame_id: str):
        store = self.store.types
        stamp = store["builtin_interfaces/msg/Time"](sec=t // 10**9, nanosec=t % 10**9)
        if self.ros1:
            return store["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame_id)
        return store["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)

    def write(self, topic: str, msgtype: str, t: int, msg) -> None:
        if topic not in self.connections:
            self.connections[topic] = self.writer.add_connection(topic, msgtype,
                                                                 typestore=self.store)
        raw = (self.store.serialize_ros1(msg, msgtype) if self.ros1
               else self.store.serialize_cdr(msg, msgtype))
        self.writer.write(self.connections[topic], t, raw)

    def image(self, topic: str, t: int, pixels: np.ndarray, encoding: str, frame_id="camera"):
        types = self.store.types
        if encoding in ("jpeg", "png"):
            ok, buf = cv2.imencode(".jpg" if encoding == "jpeg" else ".png",
                                   np.ascontiguousarray(pixels[..., ::-1]))
            assert ok
            msg = types[COMPRESSED](header=self.header(t, frame_id), format=encoding,
                                    data=buf.ravel())
            return self.write(topic, COMPRESSED, t, msg)
        if encoding == "bgr8":
            pixels = pixels[..., ::-1]
        elif encoding == "mono8":
            pixels = pixels[..., 0]
        elif encoding == "16UC1":
            pixels = np.round(pixels * 1000).astype("<u2")
        elif encoding == "32FC1":
            pixels = pixels.astype("<f4")
        data = np.ascontiguousarray(pixels).view(np.uint8).ravel()
        h, w = pixels.shape[:2]
        msg = types[IMAGE](header=self.header(t, frame_id), height=h, width=w, encoding=encoding,
                           is_bigendian=0, step=data.size // h, data=data)
        self.write(topic, IMAGE, t, msg)

    def camera_info(self, topic: str, t: int, K: np.ndarray, w: int, h: int):
        types = self.store.types
        roi = types["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0,
                                                        width=0, do_rectify=False)
        P = np.hstack([K, np.zeros((3, 1))]).ravel()
        fields = dict(header=self.header(t, "camera"), height=h, width=w,
                      distortion_model="plumb_bob", binning_x=0, binning_y=0, roi=roi)
        if self.ros1:
            msg = types[INFO](**fields, D=np.zeros(5), K=K.ravel(), R=np.eye(3).ravel(), P=P)
        else:
            msg = types[INFO](**fields, d=np.zeros(5), k=K.ravel(), r=np.eye(3).ravel(), p=P)
        self.write(topic, INFO, t, msg)

    def string(self, topic: str, t: int, text: str):
        self.write(topic, STRING, t, self.store.types[STRING](data=text))


T0 = 1_700_000_000 * 10**9  # a wall-clock epoch, as a robot's stamps are


def session_bag(session, path: Path, storage="mcap", color="rgb8", depth="16UC1",
                inspection="png", step_topic=True) -> Path:
    """The session's frames as a bag: colour, depth, inspection, camera info, step marks."""
    K = np.asarray(session.metadata["camera_K"], float)
    with BagOut(path, storage) as bag:
        for f in session.frames():
            t = T0 + f.time_ns
            rgb = f.color
            bag.image("/camera/color", t, rgb, color)
            bag.camera_info("/camera/camera_info", t, K, rgb.shape[1], rgb.shape[0])
            if depth is not None:
                bag.image("/camera/depth", t, f.depth, depth)
            if inspection is not None and f.inspection is not None:
                bag.image("/inspection/color", t, f.inspection, inspection, "inspection")
            if step_topic:
                bag.string("/step_clock", t, json.dumps(
                    {"frame": f.index, "step": f.step, "phase": f.phase}))
    return bag.path


@pytest.fixture(scope="module")
def session(recorded):
    return open_session(recorded.path)


def imported(bag_path: Path, out: Path, **options):
    options.setdefault("step_topic", "/step_clock")
    options.setdefault("frames_per_step", 2)
    import_video(ImportConfig(out=out, video=bag_path, **options))
    return open_session(out)


def expected_color(rgb: np.ndarray, encoding: str) -> np.ndarray:
    if encoding == "mono8":
        return np.repeat(rgb[..., :1], 3, axis=2)
    if encoding == "jpeg":
        _, buf = cv2.imencode(".jpg", np.ascontiguousarray(rgb[..., ::-1]))
        return cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1]
    return rgb


@pytest.mark.parametrize("storage", ["mcap", "sqlite3", "ros1"])
@pytest.mark.parametrize("color", COLOR_ENCODINGS)
def test_a_bag_imports_as_the_sessions_steps_and_frames(session, tmp_path, storage, color):
    depth = "32FC1" if color in ("bgr8", "png") else "16UC1"
    path = session_bag(session, tmp_path / "bag", storage, color, depth)
    assert is_bag(path)
    back = imported(path, tmp_path / "s.mcap", depth_topic="/camera/depth",
                    inspection_topic="/inspection/color")
    original = list(session.frames())
    frames = list(back.frames())
    assert [(f.step, f.phase) for f in frames] == [(f.step, f.phase) for f in original]
    assert [f.time_ns for f in frames] == [f.time_ns for f in original]
    for a, b in zip(original, frames, strict=True):
        # raw and lossless encodings come back bit for bit, a JPEG as the bag holds it
        np.testing.assert_array_equal(b.color, expected_color(a.color, color))
        assert np.abs(b.depth - a.depth).max() <= 0.001
        np.testing.assert_array_equal(b.inspection, a.inspection)
    K = np.asarray(back.metadata["camera_K"], float)
    np.testing.assert_allclose(K, np.asarray(session.metadata["camera_K"], float))


@pytest.fixture(scope="module")
def perceived(tmp_path_factory) -> Path:
    """A session of 3-frame steps (as the state classifier reads them), perceived."""
    from onionsort.stages import PerceiveConfig, perceive
    from tests.recordings.conftest import record

    path = tmp_path_factory.mktemp("perceived") / "original.mcap"
    record(path, n_steps=8, seed=11, frames_per_step=3)
    perceive(PerceiveConfig(sessions=[path]))
    return path


def same_perception(original: Path, imported_path: Path) -> None:
    from onionsort.stages import PerceiveConfig, perceive

    perceive(PerceiveConfig(sessions=[imported_path]))
    a = open_session(original).perceived_demonstration()
    b = open_session(imported_path).perceived_demonstration()
    assert list(a.observations) == list(b.observations)
    assert list(a.occluded) == list(b.occluded)


def test_the_perceived_demonstration_is_the_originals(perceived, tmp_path):
    """A ROS 1 bag of a session, raw colour and depth in millimetres, perceives as it."""
    path = session_bag(open_session(perceived), tmp_path / "bag", "ros1", "rgb8", "16UC1")
    out = tmp_path / "imported.mcap"
    imported(path, out, depth_topic="/camera/depth", inspection_topic="/inspection/color",
             frames_per_step=3)
    same_perception(perceived, out)


@pytest.mark.parametrize("raw_images", [False, True])
def test_export_then_import_gives_the_original(perceived, tmp_path, raw_images):
    """Our ROS 2 export imported on its own step clock: the frames bit for bit (the JPEG and
    PNG bytes themselves where exported compressed), depth to the millimetre, and the same
    perceived demonstration."""
    from onionsort.stages import ExportConfig, export_session

    bag = tmp_path / "bag"
    export_session(ExportConfig(session=perceived, out=bag, raw_images=raw_images))
    out = tmp_path / "imported.mcap"
    imported(bag, out, color_topic="/camera/color", depth_topic="/camera/depth",
             inspection_topic="/inspection/color", frames_per_step=3)
    original, back = open_session(perceived), open_session(out)
    pairs = list(zip(original.frames(), back.frames(), strict=True))
    assert [(b.step, b.phase, b.time_ns) for _, b in pairs] == [
        (a.step, a.phase, a.time_ns) for a, _ in pairs]
    for a, b in pairs:
        if raw_images:
            np.testing.assert_array_equal(b.color, a.color)
            np.testing.assert_array_equal(b.inspection, a.inspection)
        else:
            assert (b.color_jpeg, b.inspection_png) == (a.color_jpeg, a.inspection_png)
        assert b.depth_raw == a.depth_raw
    np.testing.assert_array_equal(back.metadata["camera_K"], original.metadata["camera_K"])
    np.testing.assert_array_equal(back.metadata["inspection_K"],
                                  original.metadata["inspection_K"])
    same_perception(perceived, out)


def test_a_fixed_clock_gives_the_originals_steps(session, tmp_path):
    path = session_bag(session, tmp_path / "bag", "mcap", "jpeg", None, None, False)
    back = imported(path, tmp_path / "s.mcap", step_topic=None, step_seconds=2.0)
    assert [(f.step, f.phase) for f in back.frames()] == [
        (f.step, f.phase) for f in session.frames()]
    assert back.metadata["sensors"] == {"depth": False, "inspection": False}


def test_the_colour_topic_may_be_left_out_where_there_is_one(session, tmp_path):
    path = session_bag(session, tmp_path / "bag", "mcap", "png", None, None)
    back = imported(path, tmp_path / "s.mcap")
    assert back.n_frames == session.n_frames


def test_list_names_each_topic_and_its_use(session, tmp_path, capsys):
    path = session_bag(session, tmp_path / "bag", "sqlite3", "bgr8", "16UC1", "jpeg")
    topics = {t.name: t for t in list_bag(path)}
    assert topics["/camera/color"].use == "colour (bgr8)"
    assert topics["/camera/depth"].use == "depth (16UC1)"
    assert topics["/inspection/color"].use == "colour (jpeg)"
    assert topics["/camera/camera_info"].use == "camera info"
    assert topics["/camera/color"].count == session.n_frames
    assert topics["/camera/color"].rate_hz == pytest.approx(1.0, rel=0.1)
    assert main(["import", str(path), "--list"]) == 0
    printed = capsys.readouterr().out
    assert "/camera/depth" in printed and "sensor_msgs/msg/CameraInfo" in printed
    assert "2 colour topic(s)" in printed
    # any other topic can still mark the steps
    assert any(line.startswith("/step_clock") and line.endswith("steps (--step-topic)")
               for line in printed.splitlines()), printed


def _refused(capsys, tmp_path, *argv) -> str:
    out = tmp_path / "refused.mcap"
    assert main(["import", *argv, "--out", str(out), "--step-seconds", "2"]) == 2
    assert not out.exists() and not out.with_suffix(".mcap.partial").exists()
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    return err


def test_a_bag_without_images_is_one_line_naming_its_topics(tmp_path, capsys):
    with BagOut(tmp_path / "bag", "mcap") as bag:
        bag.string("/chatter", T0, "hello")
    err = _refused(capsys, tmp_path, str(bag.path))
    assert "no image topic" in err and "/chatter (std_msgs/msg/String)" in err


def test_a_truncated_bag_is_one_line(session, tmp_path, capsys):
    path = session_bag(session, tmp_path / "bag", "ros1", "rgb8", None, None)
    data = path.read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[: len(data) // 2])
    err = _refused(capsys, tmp_path, str(cut))
    assert "cut.bag" in err


def test_an_unsupported_encoding_is_one_line(session, tmp_path, capsys):
    with BagOut(tmp_path / "bag", "mcap") as bag:
        types = ROS2.types
        msg = types[IMAGE](header=bag.header(T0, "camera"), height=2, width=2,
                           encoding="yuv422", is_bigendian=0, step=4,
                           data=np.zeros(8, np.uint8))
        bag.write("/camera/color", IMAGE, T0, msg)
    err = _refused(capsys, tmp_path, str(bag.path), "--color-topic", "/camera/color")
    assert "unsupported encoding 'yuv422'" in err


def test_depth_of_another_size_is_one_line(session, tmp_path, capsys):
    with BagOut(tmp_path / "bag", "mcap") as bag:
        for f in list(session.frames())[:4]:
            bag.image("/camera/color", T0 + f.time_ns, f.color, "rgb8")
            bag.image("/camera/depth", T0 + f.time_ns, f.depth[::2, ::2], "16UC1")
    err = _refused(capsys, tmp_path, str(bag.path), "--depth-topic", "/camera/depth")
    assert "depth of 160x120 beside colour of 320x240" in err


def test_a_missing_color_topic_lists_the_image_topics(session, tmp_path, capsys):
    path = session_bag(session, tmp_path / "bag", "mcap", "rgb8", "16UC1", None, False)
    err = _refused(capsys, tmp_path, str(path), "--color-topic", "/camera/rgb")
    assert "/camera/color" in err and "/camera/depth" in err and "/camera/rgb" in err


def test_bag_options_without_a_bag_are_refused(tmp_path):
    with pytest.raises(ValueError, match="go with a ROS bag"):
        ImportConfig(out=tmp_path / "s.mcap", camera=0, depth_topic="/camera/depth")


def test_a_step_topic_that_marks_nothing_is_refused(session, tmp_path):
    path = session_bag(session, tmp_path / "bag", "mcap", "rgb8", None, None, False)
    with pytest.raises(BagError, match="no topic '/steps'"):
        imported(path, tmp_path / "s.mcap", step_topic="/steps")


def test_a_foxglove_protobuf_file_of_another_tool_imports(session, tmp_path):
    """An MCAP file of foxglove.CompressedImage, RawImage and CameraCalibration messages written
    by mcap-protobuf-support's writer (no session record) imports like a bag."""
    from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
    from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
    from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
    from mcap_protobuf.writer import Writer

    path = tmp_path / "foxglove.mcap"
    K = np.asarray(session.metadata["camera_K"], float)
    with open(path, "wb") as f, Writer(f) as writer:
        for fr in session.frames():
            t = T0 + fr.time_ns
            stamp = {"seconds": t // 10**9, "nanos": t % 10**9}
            writer.write_message("/cam/image", CompressedImage(
                timestamp=stamp, frame_id="cam", format="jpeg", data=fr.color_jpeg), t, t)
            h, w = fr.depth_shape
            writer.write_message("/cam/depth", RawImage(
                timestamp=stamp, frame_id="cam", width=w, height=h, encoding="16UC1",
                step=2 * w, data=fr.depth_raw), t, t)
            writer.write_message("/cam/calibration", CameraCalibration(
                timestamp=stamp, frame_id="cam", width=w, height=h, K=K.ravel().tolist()), t, t)
    assert is_bag(path) and not is_bag(session.path)
    assert {t.name: t.use for t in list_bag(path)}["/cam/image"] == "colour (jpeg)"
    back = imported(path, tmp_path / "s.mcap", step_topic=None, step_seconds=2.0,
                    depth_topic="/cam/depth")
    original, frames = list(session.frames()), list(back.frames())
    assert [(f.step, f.phase) for f in frames] == [(f.step, f.phase) for f in original]
    assert [f.color_jpeg for f in frames] == [f.color_jpeg for f in original]
    assert [f.depth_raw for f in frames] == [f.depth_raw for f in original]
    np.testing.assert_allclose(np.asarray(back.metadata["camera_K"], float), K)


def test_a_raw_imports_export_labels_its_png_colour(session, tmp_path):
    """A session imported from raw images holds PNG colour; its export says so."""
    from rosbags.highlevel import AnyReader

    from onionsort.stages import ExportConfig, export_session

    path = session_bag(session, tmp_path / "bag", "mcap", "rgb8", None, None)
    imported(path, tmp_path / "s.mcap")
    export_session(ExportConfig(session=tmp_path / "s.mcap", out=tmp_path / "out"))
    with AnyReader([tmp_path / "out"], default_typestore=ROS2) as reader:
        colour = [c for c in reader.connections if c.topic == "/camera/color"]
        formats = {reader.deserialize(raw, c.msgtype).format
                   for c, _, raw in reader.messages(connections=colour)}
    assert formats == {"png"}


def test_a_folder_without_metadata_is_refused_with_what_to_do(session, tmp_path, capsys):
    path = session_bag(session, tmp_path / "bag", "mcap", "rgb8", None, None)
    (path / "metadata.yaml").unlink()
    err = _refused(capsys, tmp_path, str(path))
    assert "cannot be read as a ROS bag" in err and "ros2 bag reindex" in err
