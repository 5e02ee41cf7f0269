"""Robot bags as a session's source: ROS 2 (rosbag2, MCAP or sqlite3 storage) and ROS 1 bags.

A work cell records bags, not videos. :class:`Bag` opens one (a rosbag2 folder, one of its
``.mcap`` or ``.db3`` files, a bare ROS 2 MCAP file, or a ROS 1 ``.bag``; also an MCAP file of
Foxglove protobuf images and calibrations that another tool wrote), lists its topics
(:meth:`Bag.topics`) and reads the image topics a session is made of;
:func:`recordings.sources.importer.import_bag` writes them as one sensor-only session
(:mod:`recordings.session.schema`). Messages are read and deserialised by ``rosbags``, which
reads both ROS generations and both rosbag2 storages without a ROS install and has the standard
message types built in (``mcap-ros2-support`` reads only ROS 2 MCAP files, so it would leave
sqlite3 and ROS 1 bags out).

What is read, and how:

- **Images.** ``sensor_msgs/Image`` in ``rgb8``, ``bgr8``, ``rgba8``, ``bgra8`` or ``mono8``
  (colour), ``16UC1`` (or ``mono16``) millimetres or ``32FC1`` metres (depth), and
  ``sensor_msgs/CompressedImage`` holding a JPEG or PNG. A compressed colour image goes into
  the session as it is, and a raw one as PNG: the session's frames are the bag's pixels, with no
  second lossy compression.
- **Times** are the header stamps, or the bag's log time where a stamp is zero; a session's
  times count from its first frame.
- **Depth and the inspection view** come from other topics, matched to each colour frame by the
  nearest stamp within ``tolerance``: a colour frame with no depth that near is left out (as an
  approximate-time synchroniser would), a frame with no inspection view that near has none.
- **Intrinsics** come from a ``sensor_msgs/CameraInfo`` topic (its first message); by default
  the one beside the image topic, in the same namespace (``/camera/color`` and
  ``/camera/camera_info``), where there is exactly one.
- **Steps** come from a fixed clock, from perceived changes (as a video's,
  :mod:`onionsort.stages.import_video`), or from a topic whose messages mark step starts
  (:func:`steps_from_marks`): every message starts a step at its time, except a
  ``std_msgs/String`` holding JSON with a ``phase`` other than 0 (so that a session's own step
  clock, exported by :mod:`recordings.sources.ros_export`, marks each step once).

Only the frames a step keeps (``frames_per_step`` of each) are decoded when the steps come from
a clock or a topic; the bag is read twice (stamps first, then the kept images), so its length is
not bounded by memory.

Layouts: colour ``(H, W, 3)`` uint8 RGB; depth ``(H, W)`` float32 metres (0: no reading).
"""

from __future__ import annotations

import json
import logging
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from recordings.session.schema import SESSION_METADATA
from recordings.session.writer import EncodedImage, encode_color

__all__ = [
    "COLOR_ENCODINGS",
    "DEPTH_ENCODINGS",
    "Bag",
    "BagError",
    "BagTopic",
    "ImageStream",
    "decode_image",
    "encoded_image",
    "is_bag",
    "mcap_kind",
    "steps_from_marks",
]

logger = logging.getLogger(__name__)

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
STRING = "std_msgs/msg/String"

#: Raw colour encodings read, and how many channels each has.
COLOR_ENCODINGS = {"rgb8": 3, "bgr8": 3, "rgba8": 4, "bgra8": 4, "mono8": 1}
#: Raw depth encodings read, and the metres of one unit.
DEPTH_ENCODINGS = {"16UC1": 1e-3, "mono16": 1e-3, "32FC1": 1.0}

_JPEG_MAGIC, _PNG_MAGIC = b"\xff\xd8", b"\x89PNG"
_FOXGLOVE_CALIBRATION = "foxglove.CameraCalibration"
#: Foxglove's protobuf schemas read, as the ROS types they stand for.
_FOXGLOVE_TYPES = {"foxglove.RawImage": IMAGE, "foxglove.CompressedImage": COMPRESSED,
                   _FOXGLOVE_CALIBRATION: CAMERA_INFO}


class BagError(ValueError):
    """A bag cannot be read, or holds nothing a session can be made of; the message names the
    bag or the topic and says what to do."""


def is_bag(path: str | Path) -> bool:
    """Whether ``path`` is a bag :class:`Bag` opens (by its name and, for an MCAP file, its
    profile), not a video or an onionsort session."""
    path = Path(path)
    if path.is_dir():  # a folder is no video: read as a rosbag2 folder (or refused as one)
        return True
    if path.suffix in (".bag", ".db3"):
        return True
    if path.suffix == ".mcap" and path.is_file():  # any MCAP file but a session of ours
        return mcap_kind(path) != "session"
    return False


def mcap_kind(path: Path) -> str | None:
    """``"ros"`` (a ROS 2 MCAP), ``"foxglove"`` (Foxglove protobuf images, not a session of
    ours), ``"session"`` (an onionsort session) or None (anything else, or not MCAP)."""
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as f:
            reader = make_reader(f)
            if reader.get_header().profile in ("ros2", "ros1"):
                return "ros"
            if any(m.name == SESSION_METADATA for m in reader.iter_metadata()):
                return "session"
            summary = reader.get_summary()
    except Exception:  # not readable as MCAP: not a bag; the caller's reader says why
        return None
    if summary is None:
        return None
    names = {summary.schemas[c.schema_id].name for c in summary.channels.values()
             if c.schema_id in summary.schemas}
    return "foxglove" if names & set(_FOXGLOVE_TYPES) - {_FOXGLOVE_CALIBRATION} else None


@dataclass(frozen=True)
class BagTopic:
    """One topic of a bag, as ``onionsort import BAG --list`` prints it.

    Attributes
    ----------
    name, msgtype : str
        The topic and its message type (``sensor_msgs/msg/Image``).
    count : int
        Messages on it.
    rate_hz : float or None
        Messages a second over the bag's duration (None for fewer than two).
    use : str
        What the import can take it for (``colour``, ``depth``, ``camera info``) and the
        encoding seen, or why it cannot (``unsupported encoding yuv422``); empty for a topic
        that is none of these (any topic can mark steps, ``--step-topic``).
    """

    name: str
    msgtype: str
    count: int
    rate_hz: float | None
    use: str = ""

    @property
    def usable_image(self) -> str | None:
        """``"colour"`` or ``"depth"`` where the import can read the topic as such, else None."""
        kind = self.use.split(" ", 1)[0]
        return kind if kind in ("colour", "depth") else None


def _stamp_ns(msg: Any, log_time_ns: int) -> int:
    header = getattr(msg, "header", None)
    stamp = getattr(header, "stamp", None)
    if stamp is None:
        return int(log_time_ns)
    ns = int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
    return ns if ns > 0 else int(log_time_ns)


def _image_kind(msgtype: str, msg: Any) -> tuple[str | None, str]:
    """``(kind, detail)``: kind ``colour`` or ``depth`` (None: unusable) and the encoding."""
    if msgtype == COMPRESSED:
        data = bytes(msg.data[:4])
        fmt = str(msg.format)
        if "compresseddepth" in fmt.lower():
            return None, f"unsupported format {fmt!r} (compressedDepth)"
        if data.startswith(_JPEG_MAGIC):
            return "colour", "jpeg"
        if data.startswith(_PNG_MAGIC):
            return "colour", "png"
        return None, (f"a CompressedImage whose data is neither JPEG nor PNG (its format "
                      f"says {fmt!r}; compressed formats read: JPEG, PNG)")
    encoding = str(msg.encoding)
    if encoding in COLOR_ENCODINGS:
        return "colour", encoding
    if encoding in DEPTH_ENCODINGS:
        return "depth", encoding
    return None, (f"unsupported encoding {encoding!r} (read: "
                  f"{', '.join([*COLOR_ENCODINGS, *DEPTH_ENCODINGS])})")


def decode_image(msgtype: str, msg: Any, topic: str = "the image") -> np.ndarray:
    """An image message's pixels: colour ``(H, W, 3)`` uint8 RGB or depth ``(H, W)`` float32
    metres (NaN and infinities as 0, no reading)."""
    import cv2

    kind, detail = _image_kind(msgtype, msg)
    if kind is None:
        raise BagError(f"{topic}: {detail}")
    if msgtype == COMPRESSED:
        bgr = cv2.imdecode(np.asarray(msg.data, np.uint8), cv2.IMREAD_COLOR)
        if bgr is None:
            raise BagError(f"{topic}: a {detail} image that does not decode")
        return bgr[..., ::-1].copy()
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = np.asarray(msg.data, np.uint8)
    if h < 1 or w < 1 or step < 1 or data.size < h * step:
        raise BagError(f"{topic}: a {w}x{h} {detail} image with step {step} holds "
                       f"{data.size} bytes; the message is damaged")
    rows = data[: h * step].reshape(h, step)
    if kind == "depth":
        dtype = np.dtype("u2" if detail != "32FC1" else "f4").newbyteorder(
            ">" if msg.is_bigendian else "<")
        values = rows[:, : w * dtype.itemsize].copy().view(dtype).reshape(h, w)
        metres = values.astype(np.float32) * np.float32(DEPTH_ENCODINGS[detail])
        return np.where(np.isfinite(metres), metres, 0).astype(np.float32)
    channels = COLOR_ENCODINGS[detail]
    pixels = rows[:, : w * channels].reshape(h, w, channels)
    if detail == "mono8":
        return np.repeat(pixels, 3, axis=2)
    rgb = pixels[..., :3] if detail.startswith("rgb") else pixels[..., 2::-1]
    return np.ascontiguousarray(rgb)


def encoded_image(msgtype: str, msg: Any, topic: str) -> EncodedImage:
    """A colour message as the session stores it: a JPEG or PNG as it is (decoded once, to
    check it and read its size), a raw image as PNG."""
    rgb = decode_image(msgtype, msg, topic)
    h, w = rgb.shape[:2]
    if msgtype == COMPRESSED:
        data = bytes(msg.data)
        return EncodedImage("png" if data.startswith(_PNG_MAGIC) else "jpeg", data, w, h)
    return EncodedImage("png", encode_color(rgb, "png"), w, h)


def _intrinsics(msg: Any) -> tuple[np.ndarray, int, int]:
    """``(K, width, height)`` of a CameraInfo (ROS 2 names ``k``, ROS 1 ``K``)."""
    k = getattr(msg, "k", None)
    if k is None:
        k = msg.K
    return np.asarray(k, float).reshape(3, 3), int(msg.width), int(msg.height)


def _is_step_start(msgtype: str, msg: Any) -> bool:
    if msgtype != STRING:
        return True
    try:
        obj = json.loads(msg.data)
    except (ValueError, TypeError):
        return True
    return not (isinstance(obj, dict) and obj.get("phase", 0) != 0)


def steps_from_marks(frame_times_ns: Sequence[int], mark_times_ns: Sequence[int]) -> list[int]:
    """The step of each frame when steps start at ``mark_times_ns``: the number of marks at or
    before the frame's time, minus one (-1: before the first mark)."""
    marks = np.sort(np.asarray(mark_times_ns, np.int64))
    times = np.asarray(frame_times_ns, np.int64)
    return (np.searchsorted(marks, times, side="right") - 1).tolist()


@dataclass
class ImageStream:
    """The messages of one image topic, in the bag's order: their stamps, and what they are."""

    topic: str
    msgtype: str
    kind: str
    encoding: str
    width: int
    height: int
    stamps_ns: np.ndarray = field(repr=False)

    def nearest(self, times_ns: np.ndarray, tolerance_ns: int) -> np.ndarray:
        """The message nearest in stamp to each time, -1 where none is within tolerance."""
        order = np.argsort(self.stamps_ns, kind="stable")
        sorted_ = self.stamps_ns[order]
        if not len(sorted_):
            return np.full(len(times_ns), -1)
        right = np.clip(np.searchsorted(sorted_, times_ns), 0, len(sorted_) - 1)
        left = np.clip(right - 1, 0, len(sorted_) - 1)
        pick = np.where(np.abs(sorted_[left] - times_ns) <= np.abs(sorted_[right] - times_ns),
                        left, right)
        found = np.abs(sorted_[pick] - times_ns) <= tolerance_ns
        return np.where(found, order[pick], -1)


class Bag:
    """A ROS 2 or ROS 1 bag, opened for reading (a context manager).

    ``path`` is a rosbag2 folder (``metadata.yaml`` beside MCAP or sqlite3 files), one of its
    files, a bare ROS 2 MCAP file, or a ROS 1 ``.bag``. Opening an unreadable or truncated bag
    raises a one-line :class:`BagError`.
    """

    def __init__(self, path: str | Path) -> None:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore

        self.path = Path(path)
        if not self.path.exists():
            raise FileNotFoundError(2, "No such file or directory", str(self.path))
        self.name = str(self.path)
        try:
            if self.path.suffix == ".mcap" and mcap_kind(self.path) == "foxglove":
                self._reader = _FoxgloveReader(self.path)
            else:
                self._reader = AnyReader([self.path],
                                         default_typestore=get_typestore(Stores.ROS2_HUMBLE))
            self._reader.open()
        except Exception as exc:  # rosbags' reader errors, and what a damaged file raises
            hint = ("a rosbag2 folder needs its metadata.yaml (`ros2 bag reindex` writes it)"
                    if self.path.is_dir() and not (self.path / "metadata.yaml").is_file() else
                    "a bag a recorder was killed writing must be repaired first (`ros2 bag "
                    "reindex`, `mcap recover`, `rosbag reindex`)")
            raise BagError(f"{self.path} cannot be read as a ROS bag ({_reason(exc)}); {hint}"
                           ) from None
        self._connections = {c.topic: c for c in self._reader.connections}

    def __enter__(self) -> Bag:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self._reader.close()

    def _messages(self, topics: Sequence[str]) -> Iterator[tuple[str, int, Any]]:
        """``(topic, log time, deserialised message)`` of ``topics``, in the bag's order."""
        connections = [self._connections[t] for t in topics]
        try:
            for connection, log_time, raw in self._reader.messages(connections=connections):
                yield connection.topic, log_time, self._reader.deserialize(
                    raw, connection.msgtype)
        except BagError:
            raise
        except Exception as exc:  # a truncated chunk, a message that does not deserialise
            raise BagError(f"{self.path}: reading {', '.join(topics)} failed "
                           f"({_reason(exc)}); the bag is truncated or damaged") from None

    def _first(self, topic: str) -> Any:
        for _, _, msg in self._messages([topic]):
            return msg
        return None

    def topics(self) -> list[BagTopic]:
        """Every topic with its type, message count, rate and what the import can use it for."""
        duration_s = max(self._reader.duration, 1) / 1e9 if self._reader.connections else 0.0
        out = []
        for topic, c in sorted(self._connections.items()):
            count = sum(x.msgcount for x in self._reader.connections if x.topic == topic)
            rate = (count - 1) / duration_s if count > 1 and duration_s > 0 else None
            use = ""
            if c.msgtype in (IMAGE, COMPRESSED) and count:
                kind, detail = _image_kind(c.msgtype, self._first(topic))
                use = f"{kind} ({detail})" if kind else detail
            elif c.msgtype == CAMERA_INFO:
                use = "camera info"
            out.append(BagTopic(topic, c.msgtype, count, rate, use))
        return out

    def image_topics(self) -> list[BagTopic]:
        return [t for t in self.topics() if t.msgtype in (IMAGE, COMPRESSED)]

    def _require(self, topic: str, option: str, types: Sequence[str]) -> None:
        if topic not in self._connections:
            images = [t.name for t in self.image_topics()]
            raise BagError(f"{self.path} has no topic {topic!r} ({option}); its image topics: "
                           f"{', '.join(images) if images else 'none'}")
        msgtype = self._connections[topic].msgtype
        if msgtype not in types:
            raise BagError(f"{option} {topic} is a {msgtype}; it must be a "
                           f"{' or '.join(types)}")

    def color_topic(self, topic: str | None, taken: Sequence[str | None] = ()) -> str:
        """``topic``, checked; or, when None, the bag's one usable colour topic apart from
        those ``taken`` (the inspection view's)."""
        if topic is not None:
            self._require(topic, "--color-topic", (IMAGE, COMPRESSED))
            return topic
        topics = self.topics()
        colour = [t.name for t in topics if t.usable_image == "colour" and t.name not in taken]
        if len(colour) == 1:
            return colour[0]
        if not colour:
            listed = ", ".join(f"{t.name} ({t.msgtype})" for t in topics) or "none"
            raise BagError(f"{self.path} has no image topic the import can read; its topics: "
                           f"{listed}")
        raise BagError(f"{self.path} has {len(colour)} colour image topics "
                       f"({', '.join(colour)}); choose one with --color-topic")

    def camera_info_beside(self, image_topic: str) -> str | None:
        """The one CameraInfo topic in the namespace of ``image_topic``, if there is one."""
        namespace = image_topic.rsplit("/", 1)[0] + "/"
        beside = [t for t, c in self._connections.items()
                  if c.msgtype == CAMERA_INFO and t.startswith(namespace)
                  and "/" not in t[len(namespace):]]
        return beside[0] if len(beside) == 1 else None

    def intrinsics(self, topic: str, option: str = "--camera-info-topic"
                   ) -> tuple[np.ndarray, int, int]:
        """``(K, width, height)`` from the first CameraInfo on ``topic``."""
        self._require(topic, option, (CAMERA_INFO,))
        msg = self._first(topic)
        if msg is None:
            raise BagError(f"{option} {topic} has no message")
        K, w, h = _intrinsics(msg)
        if not (np.all(np.isfinite(K)) and K[0, 0] > 0 and K[1, 1] > 0):
            raise BagError(f"{option} {topic}: its K {K.ravel().tolist()} is not a pinhole "
                           "calibration (fx, fy > 0)")
        return K, w, h

    def stream(self, topic: str, option: str, kind: str | None = None) -> ImageStream:
        """Scan the image ``topic`` for its stamps; ``kind`` (colour or depth) is required of
        it where given."""
        self._require(topic, option, (IMAGE, COMPRESSED))
        msgtype = self._connections[topic].msgtype
        stamps, logged, first = [], [], None
        for _, log_time, msg in self._messages([topic]):
            if first is None:
                first = msg
            stamps.append(_stamp_ns(msg, log_time))
            logged.append(int(log_time))
        if first is None:
            raise BagError(f"{option} {topic} has no message")
        found, encoding = _image_kind(msgtype, first)
        if found is None:
            raise BagError(f"{option} {topic}: {encoding}")
        if kind is not None and found != kind:
            raise BagError(f"{option} {topic} holds {found} images ({encoding}); it must hold "
                           f"{kind}")
        times = np.asarray(stamps, np.int64)
        if np.any(np.diff(times) < 0):
            logger.warning("%s: header stamps go backwards; its frames are timed by the bag's "
                           "log time instead", topic)
            times = np.asarray(logged, np.int64)
        h, w = decode_image(msgtype, first, topic).shape[:2]
        return ImageStream(topic, msgtype, found, encoding, w, h, times)

    def marks(self, topic: str) -> np.ndarray:
        """The step starts that ``topic``'s messages mark (see the module docstring)."""
        if topic not in self._connections:
            raise BagError(f"{self.path} has no topic {topic!r} (--step-topic); its topics: "
                           f"{', '.join(sorted(self._connections)) or 'none'}")
        msgtype = self._connections[topic].msgtype
        out = [_stamp_ns(msg, t) for _, t, msg in self._messages([topic])
               if _is_step_start(msgtype, msg)]
        if not out:
            raise BagError(f"--step-topic {topic} marks no step start")
        return np.asarray(out, np.int64)

    def read(self, topics: Sequence[str], wanted: dict[str, set[int]]
             ) -> Iterator[tuple[str, int, str, Any]]:
        """``(topic, index, msgtype, message)`` of the messages ``wanted[topic]`` holds the
        index of (their position on the topic), in the bag's order."""
        counters = dict.fromkeys(topics, 0)
        for topic, _, msg in self._messages(topics):
            i = counters[topic]
            counters[topic] += 1
            if i in wanted.get(topic, ()):
                yield topic, i, self._connections[topic].msgtype, msg


@dataclass(frozen=True)
class _Channel:
    topic: str
    msgtype: str
    msgcount: int


class _Time:
    def __init__(self, timestamp) -> None:
        self.sec, self.nanosec = int(timestamp.seconds), int(timestamp.nanos)


class _Header:
    def __init__(self, msg) -> None:
        self.stamp, self.frame_id = _Time(msg.timestamp), msg.frame_id


class _FoxgloveMessage:
    """A Foxglove protobuf image or calibration under the names of its ROS counterpart (header
    stamp, ``k``, ``is_bigendian``, data as a uint8 array)."""

    def __init__(self, msg) -> None:
        self._msg = msg
        self.header = _Header(msg)
        self.data = np.frombuffer(msg.data, np.uint8) if hasattr(msg, "data") else None
        self.is_bigendian = 0
        if hasattr(msg, "K"):
            self.k = list(msg.K)

    def __getattr__(self, name: str):
        return getattr(self._msg, name)


class _FoxgloveReader:
    """The part of ``rosbags``' reader that :class:`Bag` uses, over an MCAP file of Foxglove
    protobuf messages (``foxglove.RawImage``, ``CompressedImage``, ``CameraCalibration``)
    written by another tool; its other topics are listed, not read."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._file = None
        self.connections: list[_Channel] = []
        self.duration = 0

    def open(self) -> None:
        from mcap.reader import make_reader
        from mcap_protobuf.decoder import DecoderFactory

        self._file = open(self.path, "rb")  # noqa: SIM115 (closed by close())
        self._mcap = make_reader(self._file, decoder_factories=[DecoderFactory()])
        summary = self._mcap.get_summary()
        if summary is None:
            raise ValueError("it has no summary section")
        stats = summary.statistics
        counts = stats.channel_message_counts if stats is not None else {}
        for cid, channel in sorted(summary.channels.items()):
            schema = summary.schemas.get(channel.schema_id)
            name = schema.name if schema is not None else "(no schema)"
            self.connections.append(_Channel(channel.topic, _FOXGLOVE_TYPES.get(name, name),
                                             int(counts.get(cid, 0))))
        if stats is not None:
            self.duration = int(stats.message_end_time - stats.message_start_time)

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None

    def messages(self, connections: Sequence[_Channel]):
        by_topic = {c.topic: c for c in connections}
        for _, channel, message, decoded in self._mcap.iter_decoded_messages(
                topics=list(by_topic)):
            yield by_topic[channel.topic], message.log_time, decoded

    def deserialize(self, decoded, msgtype: str):
        return _FoxgloveMessage(decoded)


def _reason(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) < 200 else text[:197] + "..."
