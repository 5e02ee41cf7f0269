"""Export a session as a rosbag2 folder that ROS 2 tools play (the library side of
``onionsort export --format ros2``).

:func:`export_ros2` writes one rosbag2 folder (``metadata.yaml`` and one storage file, MCAP by
default, or SQLite 3) of CDR-serialised ROS 2 Humble messages, with rosbags' own writer. The
topic mapping is a contract that the bag import (:mod:`recordings.sources.bags`) relies on:

=======================  ==============================  =====================================
topic                    ROS 2 type                      content
=======================  ==============================  =====================================
/camera/color            sensor_msgs/CompressedImage     format ``jpeg``: the session's JPEG
                                                         bytes unchanged, every frame (with
                                                         ``raw_images``: sensor_msgs/Image
                                                         ``rgb8``, decoded)
/camera/depth            sensor_msgs/Image               ``16UC1`` millimetres, the session's
                                                         bytes unchanged (little-endian); where
                                                         the session has depth
/camera/camera_info      sensor_msgs/CameraInfo          every frame: width, height, ``k``
                                                         (K row-major), ``p`` = [K | 0], ``r``
                                                         identity, ``d`` five zeros,
                                                         ``plumb_bob``
/inspection/color        sensor_msgs/CompressedImage     format ``png``, the session's bytes
                                                         unchanged, on the frames that have one
                                                         (``raw_images``: Image ``rgb8``)
/inspection/camera_info  sensor_msgs/CameraInfo          alongside each inspection image
/tf                      tf2_msgs/TFMessage              the frame's transforms (child ->
                                                         parent), where the session has them
/joint_states            sensor_msgs/JointState          a robot's joint positions
/step_clock              std_msgs/String                 JSON ``{"frame", "step", "phase"}``,
                                                         every frame
/onionsort/session       std_msgs/String                 JSON of the session record, once, at
                                                         the first frame's time
/onionsort/robot         std_msgs/String                 JSON of the robot record, once, where
                                                         the session has a robot
every other JSON topic   std_msgs/String                 the message's JSON text unchanged, at
                                                         its time, under the same name
                                                         (``/perception/*``, ``/evaluation/*``,
                                                         ``/ground_truth/*``)
=======================  ==============================  =====================================

The images' ``frame_id`` is ``camera`` or ``inspection`` (the optical frames ``/tf`` places).
Every message's header stamp and its log time in the bag are the session's ``time_ns``, kept as
they are (sessions start near 0). Topics in Foxglove protobuf schemas that have no plain ROS 2
counterpart (``/ground_truth/annotations``, ``/perception/annotations``: drawings of boxes the
JSON topics hold; ``/scene``: the simulated world's bodies) are left out and listed in
:attr:`ExportSummary.skipped`.

Layouts: ``K`` (3, 3) row-major; decoded images ``(H, W, 3)`` uint8 RGB; depth ``(H, W)``
uint16 millimetres, little-endian.

The folder is written under a temporary sibling (``<out>.partial/<name>``) and renamed to
``out_dir`` once complete; on any error the temporary folder is removed, so a failed export
leaves nothing behind.
"""

from __future__ import annotations

import json
import logging
import shutil
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from mcap.reader import make_reader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from recordings.session.reader import FrameRecord, RecordingDamagedError, Session, open_session
from recordings.session.schema import Topic

__all__ = ["ROBOT_TOPIC", "SESSION_TOPIC", "STORAGES", "ExportSummary", "RosTopic",
           "export_ros2"]

logger = logging.getLogger(__name__)

#: Storage plugins of the rosbag2 folder, by the name the CLI takes.
STORAGES = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}
#: The session record, once, as JSON.
SESSION_TOPIC = "/onionsort/session"
#: The robot record of a session with a robot, once, as JSON.
ROBOT_TOPIC = "/onionsort/robot"
_BAG_VERSION = 9


class RosTopic:
    """Topic names of an exported bag that differ from the session's."""

    CAMERA_INFO = "/camera/camera_info"
    INSPECTION_INFO = "/inspection/camera_info"


#: Session topics the frames carry (read through :func:`open_session`) or that become
#: CameraInfo; every other JSON topic is copied as a std_msgs/String.
_FRAME_TOPICS = frozenset({Topic.COLOR, Topic.DEPTH, Topic.STEP_CLOCK, Topic.INSPECTION,
                           Topic.TF, Topic.JOINT_STATES, Topic.CALIBRATION,
                           Topic.INSPECTION_CALIBRATION})

_COMPRESSED = "sensor_msgs/msg/CompressedImage"
_IMAGE = "sensor_msgs/msg/Image"
_CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
_TF = "tf2_msgs/msg/TFMessage"
_JOINTS = "sensor_msgs/msg/JointState"
_STRING = "std_msgs/msg/String"


@dataclass(frozen=True)
class ExportSummary:
    """What :func:`export_ros2` wrote.

    Attributes
    ----------
    path : Path
        The rosbag2 folder.
    storage : str
        ``mcap`` or ``sqlite3``.
    n_frames : int
        Frames of the session exported.
    raw_images : bool
        Whether the images were decoded to ``rgb8`` Images.
    topics : dict of str -> (str, int)
        Each topic of the bag: its ROS 2 message type and message count.
    skipped : tuple of str
        Topics of the session with no ROS 2 counterpart, left out.
    """

    path: Path
    storage: str
    n_frames: int
    raw_images: bool
    topics: dict[str, tuple[str, int]] = field(default_factory=dict)
    skipped: tuple[str, ...] = ()

    @property
    def n_messages(self) -> int:
        return sum(count for _, count in self.topics.values())


@dataclass(frozen=True)
class _Calibration:
    """A pinhole camera: ``K`` (3, 3), the image's width and height."""

    K: np.ndarray
    width: int
    height: int


@dataclass
class _SideTopics:
    """What the frames do not carry: each camera's calibration by frame, and the JSON
    messages of the other topics ``(time_ns, topic, text)`` in time order."""

    calibrations: dict[str, dict[int, _Calibration]]
    json_messages: list[tuple[int, str, str]]
    skipped: tuple[str, ...]


def _side_topics(path: Path) -> _SideTopics:
    """Read the calibrations and the other JSON topics of a session that opened cleanly."""
    calibrations: dict[str, dict[int, _Calibration]] = {Topic.CALIBRATION: {},
                                                        Topic.INSPECTION_CALIBRATION: {}}
    messages: list[tuple[int, str, str]] = []
    skipped: set[str] = set()
    with path.open("rb") as fh:
        for _, channel, msg in make_reader(fh, validate_crcs=True).iter_messages(
                log_time_order=False):
            topic = channel.topic
            if topic in calibrations:
                cal = CameraCalibration.FromString(msg.data)
                calibrations[topic][int(msg.sequence)] = _Calibration(
                    np.asarray(cal.K, float).reshape(3, 3), int(cal.width), int(cal.height))
            elif topic in _FRAME_TOPICS:
                continue
            elif channel.message_encoding == "json":
                messages.append((int(msg.log_time), topic, bytes(msg.data).decode()))
            else:
                skipped.add(topic)
    messages.sort(key=lambda m: m[0])  # stable: messages of one time keep their file order
    return _SideTopics(calibrations, messages, tuple(sorted(skipped)))


class _Bag:
    """A rosbag2 writer that adds each topic's connection on its first message and counts."""

    def __init__(self, writer: Writer, typestore) -> None:
        self.writer, self.ts = writer, typestore
        self.types = typestore.types
        self._connections: dict[str, object] = {}
        self.topics: dict[str, tuple[str, int]] = {}

    def write(self, topic: str, msg, time_ns: int) -> None:
        msgtype = msg.__msgtype__
        conn = self._connections.get(topic)
        if conn is None:
            conn = self._connections[topic] = self.writer.add_connection(
                topic, msgtype, typestore=self.ts)
        self.writer.write(conn, int(time_ns), self.ts.serialize_cdr(msg, msgtype))
        self.topics[topic] = (msgtype, self.topics.get(topic, ("", 0))[1] + 1)

    # -- messages ------------------------------------------------------------------------------
    def header(self, time_ns: int, frame_id: str):
        sec, nanosec = divmod(int(time_ns), 1_000_000_000)
        return self.types["std_msgs/msg/Header"](
            stamp=self.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec),
            frame_id=frame_id)

    def compressed(self, data: bytes, fmt: str, time_ns: int, frame_id: str):
        return self.types[_COMPRESSED](header=self.header(time_ns, frame_id), format=fmt,
                                       data=np.frombuffer(data, np.uint8))

    def image(self, pixels: np.ndarray, encoding: str, bytes_per_pixel: int, time_ns: int,
              frame_id: str):
        """A sensor_msgs/Image of ``pixels`` (H, W[, C]) in ``encoding``, little-endian."""
        h, w = pixels.shape[:2]
        data = np.frombuffer(np.ascontiguousarray(pixels).tobytes(), np.uint8)
        return self.types[_IMAGE](header=self.header(time_ns, frame_id), height=h, width=w,
                                  encoding=encoding, is_bigendian=0, step=bytes_per_pixel * w,
                                  data=data)

    def camera_info(self, cal: _Calibration, time_ns: int, frame_id: str):
        P = np.zeros((3, 4))
        P[:, :3] = cal.K
        roi = self.types["sensor_msgs/msg/RegionOfInterest"](
            x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
        return self.types[_CAMERA_INFO](
            header=self.header(time_ns, frame_id), height=cal.height, width=cal.width,
            distortion_model="plumb_bob", d=np.zeros(5), k=cal.K.astype(float).ravel(),
            r=np.eye(3).ravel(), p=P.ravel(), binning_x=0, binning_y=0, roi=roi)

    def tf(self, transforms: dict, time_ns: int):
        t = self.types
        return t[_TF](transforms=[
            t["geometry_msgs/msg/TransformStamped"](
                header=self.header(time_ns, parent), child_frame_id=child,
                transform=t["geometry_msgs/msg/Transform"](
                    translation=t["geometry_msgs/msg/Vector3"](*map(float, translation)),
                    rotation=t["geometry_msgs/msg/Quaternion"](*map(float, rotation))))
            for child, (parent, translation, rotation) in transforms.items()])

    def joint_state(self, joints: dict[str, float], time_ns: int):
        return self.types[_JOINTS](
            header=self.header(time_ns, ""), name=list(joints),
            position=np.array(list(joints.values()), float), velocity=np.zeros(0),
            effort=np.zeros(0))

    def string(self, text: str):
        return self.types[_STRING](data=text)


def _json(doc) -> str:
    return json.dumps(doc, sort_keys=True, separators=(",", ":"))


class _Cameras:
    """Each camera's calibration at a frame: the frame's own calibration message, else the
    last one before it, else the session record's K with the image's size."""

    def __init__(self, session: Session, side: _SideTopics) -> None:
        self._by_frame = side.calibrations
        self._K = {Topic.CALIBRATION: session.metadata.get("camera_K"),
                   Topic.INSPECTION_CALIBRATION: session.metadata.get("inspection_K")}
        self._last: dict[str, _Calibration | None] = dict.fromkeys(self._K)

    def at(self, topic: str, index: int, image) -> _Calibration | None:
        """``image()`` gives the decoded image, called only for the record's fallback."""
        cal = self._by_frame[topic].get(index, self._last[topic])
        if cal is None and self._K[topic] is not None:
            h, w = image().shape[:2]
            cal = _Calibration(np.asarray(self._K[topic], float).reshape(3, 3), w, h)
        self._last[topic] = cal
        return cal


def _format(data: bytes) -> str:
    """``png`` or ``jpeg``, by the compressed image's own signature (a session's colour is
    JPEG, or PNG where it was imported from raw images; its inspection views PNG)."""
    return "png" if data[:4] == b"\x89PNG" else "jpeg"


def _frame_messages(bag: _Bag, frame: FrameRecord, cameras: _Cameras, raw_images: bool
                    ) -> Iterator[tuple[str, object]]:
    """The ``(topic, message)`` pairs of one frame, in the order they are written."""
    t = frame.time_ns
    yield Topic.COLOR, (bag.image(frame.color, "rgb8", 3, t, "camera") if raw_images
                        else bag.compressed(frame.color_jpeg, _format(frame.color_jpeg), t,
                                            "camera"))
    if frame.depth_raw is not None:
        mm = np.frombuffer(frame.depth_raw, "<u2").reshape(frame.depth_shape)
        yield Topic.DEPTH, bag.image(mm, "16UC1", 2, t, "camera")
    cal = cameras.at(Topic.CALIBRATION, frame.index, lambda: frame.color)
    if cal is not None:
        yield RosTopic.CAMERA_INFO, bag.camera_info(cal, t, "camera")
    if frame.inspection_png is not None:
        yield Topic.INSPECTION, (
            bag.image(frame.inspection, "rgb8", 3, t, "inspection") if raw_images
            else bag.compressed(frame.inspection_png, _format(frame.inspection_png), t,
                                "inspection"))
        cal = cameras.at(Topic.INSPECTION_CALIBRATION, frame.index, lambda: frame.inspection)
        if cal is not None:
            yield RosTopic.INSPECTION_INFO, bag.camera_info(cal, t, "inspection")
    if frame.transforms:
        yield Topic.TF, bag.tf(frame.transforms, t)
    if frame.joints:
        yield Topic.JOINT_STATES, bag.joint_state(frame.joints, t)
    yield Topic.STEP_CLOCK, bag.string(
        _json({"frame": frame.index, "step": frame.step, "phase": frame.phase}))


def _write_session(bag: _Bag, session: Session, side: _SideTopics, raw_images: bool) -> None:
    frames = list(session.frames())
    start = min((f.time_ns for f in frames), default=0)
    bag.write(SESSION_TOPIC, bag.string(_json(session.metadata)), start)
    if session.robot is not None:
        bag.write(ROBOT_TOPIC, bag.string(_json(session.robot)), start)
    cameras = _Cameras(session, side)
    pending = iter(side.json_messages)
    nxt = next(pending, None)
    for frame in frames:
        while nxt is not None and nxt[0] <= frame.time_ns:  # the other topics, in time order
            bag.write(nxt[1], bag.string(nxt[2]), nxt[0])
            nxt = next(pending, None)
        for topic, msg in _frame_messages(bag, frame, cameras, raw_images):
            bag.write(topic, msg, frame.time_ns)
    while nxt is not None:
        bag.write(nxt[1], bag.string(nxt[2]), nxt[0])
        nxt = next(pending, None)


def export_ros2(session_path: str | Path, out_dir: str | Path, *, raw_images: bool = False,
                storage: str = "mcap") -> ExportSummary:
    """Write a session as a rosbag2 folder that ROS 2 tools play (see the module docstring).

    Parameters
    ----------
    session_path : path-like
        A session ``.mcap`` (:func:`recordings.open_session`); a damaged one is refused.
    out_dir : path-like
        The rosbag2 folder to create; its storage file is ``<name>.mcap`` (or ``.db3``).
    raw_images : bool
        Decode the colour and inspection images into ``rgb8`` sensor_msgs/Image instead of
        copying the compressed bytes.
    storage : {"mcap", "sqlite3"}
        The rosbag2 storage plugin.

    Returns
    -------
    ExportSummary

    Raises
    ------
    FileExistsError
        If ``out_dir`` exists.
    NotASessionError, RecordingDamagedError
        If ``session_path`` is not a session, or a truncated or corrupt one.
    ValueError
        If ``storage`` is not one of :data:`STORAGES`.
    """
    if storage not in STORAGES:
        raise ValueError(f"storage must be one of {', '.join(STORAGES)}; got {storage!r}")
    out = Path(out_dir)
    if out.exists():
        raise FileExistsError(f"{out} exists; choose another --out or remove it")
    source = Path(session_path)
    session = open_session(source)
    try:
        side = _side_topics(source)
    except Exception as exc:  # it opened cleanly: damage that the reader's scan let through
        raise RecordingDamagedError(f"{source} is corrupt: reading its topics failed "
                                    f"({type(exc).__name__}: {exc})") from None
    staging = out.with_name(out.name + ".partial")
    if staging.exists():
        logger.warning("%s: removing the temporary folder of an earlier export", staging)
        shutil.rmtree(staging)
    try:
        staging.mkdir(parents=True)
        bag_dir = staging / out.name
        with Writer(bag_dir, version=_BAG_VERSION, storage_plugin=STORAGES[storage]) as writer:
            bag = _Bag(writer, get_typestore(Stores.ROS2_HUMBLE))
            _write_session(bag, session, side, bool(raw_images))
        bag_dir.rename(out)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    if side.skipped:
        logger.info("%s: left out %s (no ROS 2 counterpart)", out, ", ".join(side.skipped))
    summary = ExportSummary(path=out, storage=storage, n_frames=session.n_frames,
                            raw_images=bool(raw_images), topics=dict(bag.topics),
                            skipped=side.skipped)
    logger.info("%s: %d messages on %d topics from %d frames of %s", out, summary.n_messages,
                len(summary.topics), summary.n_frames, source)
    return summary
