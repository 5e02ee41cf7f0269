"""Read a session back: its frames with labels, its steps, and its demonstration for ``irl``.

The file is scanned sequentially with CRC validation, so a truncated file (a recording killed
outright) or a corrupt one is detected at the first bad record; everything before it is
recovered. Opening such a file raises :class:`RecordingDamagedError` naming the file and what
was recovered, unless ``recover=True``.

Layouts: ``color[v, u, c]`` (H, W, 3) uint8 RGB, ``depth[v, u]`` (H, W) float32 metres.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mcap.records import Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from irl.demonstrations import Demonstration, Trajectory
from irl.domains.onion_sorting import N_ACTIONS
from recordings.perception import PERCEPTION_METADATA, PerceptionTopic
from recordings.schema import END_METADATA, FORMAT_NAME, SESSION_METADATA, Topic
from robot.labels import StepLabel

__all__ = [
    "FrameRecord",
    "NotASessionError",
    "RecordingDamagedError",
    "Session",
    "open_session",
    "read_demonstrations",
]

logger = logging.getLogger(__name__)

_MAGIC = b"\x89MCAP0\r\n"


class NotASessionError(ValueError):
    """The file is not an MCAP file, or an MCAP file that is not an onionsort session."""


class RecordingDamagedError(ValueError):
    """The file is truncated or corrupt; the message says what could be recovered."""


@dataclass(frozen=True)
class FrameRecord:
    """One recorded frame: its images (decoded on demand) and its ground truth.

    ``state`` holds the ``/ground_truth/state`` message, ``boxes`` and ``onions`` the lists of
    the ``/ground_truth/boxes`` and ``/ground_truth/onions`` messages.
    """

    index: int
    time_ns: int
    state: dict
    boxes: list[dict]
    onions: list[dict]
    color_jpeg: bytes = field(repr=False)
    depth_raw: bytes = field(repr=False)
    depth_shape: tuple[int, int] = (0, 0)
    inspection_png: bytes | None = field(default=None, repr=False)

    @property
    def step(self) -> int:
        return int(self.state["step"])

    @property
    def occluded(self) -> bool:
        return bool(self.state["occluded"])

    @property
    def color(self) -> np.ndarray:
        """The main camera's image, (H, W, 3) uint8 RGB."""
        return _decode_image(self.color_jpeg)

    @property
    def depth(self) -> np.ndarray:
        """Depth in metres, (H, W) float32 (0 where there was no reading)."""
        mm = np.frombuffer(self.depth_raw, dtype="<u2").reshape(self.depth_shape)
        return mm.astype(np.float32) / 1000.0

    @property
    def inspection(self) -> np.ndarray | None:
        """The inspection view, (h, w, 3) uint8 RGB, on a step's first frame; else None."""
        return None if self.inspection_png is None else _decode_image(self.inspection_png)


def _decode_image(data: bytes) -> np.ndarray:
    import cv2

    bgr = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    if bgr is None:
        raise ValueError("could not decode a compressed image of the recording")
    return bgr[..., ::-1].copy()


@dataclass
class Session:
    """A session read from its MCAP file.

    Attributes
    ----------
    path : Path
    metadata : dict
        The ``onionsort.session`` record, JSON values decoded.
    status : str
        ``complete``, ``interrupted`` (stopped, file finished) or ``damaged`` (truncated or
        corrupt, opened with ``recover=True``).
    steps : list of StepLabel
        The ground-truth steps, in order.
    problem : str or None
        What was wrong with a damaged file.
    perception : dict of int -> dict
        The ``/perception/state`` message of each perceived step (empty if the session was
        not perceived; see :mod:`recordings.perception`).
    perception_models : dict or None
        The ``onionsort.perception`` record: which models perceived the session.
    """

    path: Path
    metadata: dict
    status: str
    steps: list[StepLabel]
    _frames: list[FrameRecord] = field(repr=False)
    problem: str | None = None
    perception: dict[int, dict] = field(default_factory=dict, repr=False)
    perception_models: dict | None = None

    def __len__(self) -> int:
        return len(self._frames)

    @property
    def n_frames(self) -> int:
        return len(self._frames)

    def frames(self) -> Iterator[FrameRecord]:
        """The frames in order, each with its ground-truth labels."""
        return iter(self._frames)

    def trajectory(self) -> Trajectory:
        """Ground-truth states and actions of the steps, shape (T,) each."""
        return Trajectory(states=np.array([s.state for s in self.steps], np.int64),
                          actions=np.array([s.action for s in self.steps], np.int64))

    @property
    def occluded(self) -> np.ndarray:
        """Which steps the passer-by occluded, bool (T,)."""
        return np.array([s.occluded for s in self.steps], bool)

    def demonstration(self) -> Demonstration:
        """The session as a demonstration of ``(s, a)`` pairs from ground truth.

        Observation ``o = s * 5 + a`` (the identity observation model of
        :meth:`irl.demonstrations.Demonstration.from_pairs`), None at occluded steps.
        """
        if not self.steps:
            raise ValueError(f"{self.path}: the session holds no complete step")
        traj = self.trajectory()
        return Demonstration.from_pairs(traj.states, traj.actions, N_ACTIONS,
                                        occluded=self.occluded)

    def perceived_demonstration(self) -> Demonstration:
        """The session as perception saw it: pair observations ``o = s * 5 + a`` of the
        perceived state and action, None exactly where the classifier said occluded.

        Raises
        ------
        ValueError
            If the session has no perception topics (run ``onionsort perceive`` on it), or a
            step lacks its perception.
        """
        if not self.perception:
            raise ValueError(f"{self.path} has no perception topics; run `onionsort perceive "
                             f"{self.path}` first")
        if not self.steps:
            raise ValueError(f"{self.path}: the session holds no complete step")
        missing = [s.step for s in self.steps if s.step not in self.perception]
        if missing:
            raise ValueError(f"{self.path}: steps {missing[:5]} have no perception (the "
                             "session was perceived before it was complete?)")
        obs = [self.perception[s.step]["observation"] for s in self.steps]
        return Demonstration(obs)


def _scan(path: Path):
    """Yield (schema, channel, message) and metadata records; return via exceptions on damage."""
    with path.open("rb") as fh:
        channels: dict[int, Channel] = {}
        for record in StreamReader(fh, validate_crcs=True).records:
            if isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message):
                yield "message", channels[record.channel_id].topic, record
            elif isinstance(record, Metadata):
                yield "metadata", record.name, record
            elif isinstance(record, Schema):
                continue


def _check_magic(path: Path) -> None:
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such recording")
    with path.open("rb") as fh:
        head = fh.read(len(_MAGIC))
    if head != _MAGIC:
        raise NotASessionError(
            f"{path} is not an MCAP file (it does not start with the MCAP magic bytes)")


def open_session(path: str | Path, *, recover: bool = False) -> Session:
    """Open a recorded session.

    Parameters
    ----------
    path : path-like
        A ``.mcap`` file written by ``onionsort record``.
    recover : bool
        Accept a truncated or corrupt file and keep every complete frame and step before the
        damage (logged as a warning). Without it such a file raises.

    Raises
    ------
    NotASessionError
        If the file is not MCAP, or is MCAP without an ``onionsort.session`` record.
    RecordingDamagedError
        If the file is truncated or corrupt and ``recover`` is False; the message names the
        file and how many frames and steps were recovered.
    """
    path = Path(path)
    _check_magic(path)
    meta: dict | None = None
    end: dict | None = None
    parts: dict[int, dict] = {}
    steps: dict[int, StepLabel] = {}
    perception: dict[int, dict] = {}
    models = None
    problem = None
    try:
        for kind, name, rec in _scan(path):
            if kind == "metadata":
                if name == SESSION_METADATA:
                    meta = dict(rec.metadata)
                elif name == END_METADATA:
                    end = dict(rec.metadata)
                elif name == PERCEPTION_METADATA:
                    models = _decode_metadata(dict(rec.metadata))
                continue
            if meta is None:
                break  # a session's metadata precedes every message
            if name == PerceptionTopic.STATE:
                msg = json.loads(rec.data)
                perception[int(msg["step"])] = msg
                continue
            _collect(name, rec, parts, steps)
    except Exception as exc:  # any failure to parse the rest is damage: CRC, EOF, zstd, struct
        problem = (f"{type(exc).__name__}: {exc}" if str(exc)
                   else f"{type(exc).__name__}: the file ends in the middle of a record")
    if meta is None and problem:
        raise RecordingDamagedError(
            f"{path} is truncated or corrupt before its session metadata ({problem}); "
            f"recovered nothing from {path.stat().st_size} bytes")
    if meta is None or meta.get("format") != FORMAT_NAME:
        raise NotASessionError(
            f"{path} is an MCAP file but not an onionsort session (no '{SESSION_METADATA}' "
            f"metadata record with format '{FORMAT_NAME}')"
            + (f"; reading it failed with {problem}" if problem else ""))
    frames = [_assemble(i, parts[i]) for i in sorted(parts) if _complete(parts[i])]
    complete_steps = [steps[t] for t in sorted(steps)]
    if problem is None and end is None:
        problem = "no end record"
    status = "damaged" if problem else end.get("status", "complete")
    if problem:
        message = (
            f"{path} is truncated or corrupt ({problem}); recovered {len(frames)} complete "
            f"frames and {len(complete_steps)} steps from {path.stat().st_size} bytes")
        if not recover:
            raise RecordingDamagedError(message + "; open it with recover=True to use them")
        logger.warning("%s", message)
    return Session(path=path, metadata=_decode_metadata(meta), status=status,
                   steps=complete_steps, _frames=frames, problem=problem,
                   perception=perception, perception_models=models)


def _decode_metadata(meta: dict) -> dict:
    out = {}
    for k, v in meta.items():
        try:
            out[k] = json.loads(v)
        except (json.JSONDecodeError, TypeError):
            out[k] = v
    return out


def _collect(topic: str, rec: Message, parts: dict[int, dict], steps: dict[int, StepLabel]):
    if topic == Topic.ACTION:
        m = json.loads(rec.data)
        steps[int(m["step"])] = StepLabel(step=int(m["step"]), state=int(m["state"]),
                                          action=int(m["action"]),
                                          next_state=int(m["next_state"]),
                                          occluded=bool(m["occluded"]))
        return
    part = parts.setdefault(int(rec.sequence), {"time_ns": rec.log_time})
    if topic in (Topic.COLOR, Topic.INSPECTION):
        from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage

        part[topic] = CompressedImage.FromString(rec.data).data
    elif topic == Topic.DEPTH:
        from foxglove_schemas_protobuf.RawImage_pb2 import RawImage

        msg = RawImage.FromString(rec.data)
        if msg.encoding != "16UC1":
            raise ValueError(f"depth encoding must be 16UC1; got {msg.encoding!r}")
        part[topic] = (bytes(msg.data), (msg.height, msg.width))
    elif topic in (Topic.STATE, Topic.BOXES, Topic.ONIONS):
        part[topic] = json.loads(rec.data)


def _complete(part: dict) -> bool:
    return all(t in part for t in (Topic.COLOR, Topic.DEPTH, Topic.STATE, Topic.BOXES,
                                   Topic.ONIONS))


def _assemble(index: int, part: dict) -> FrameRecord:
    depth, shape = part[Topic.DEPTH]
    return FrameRecord(
        index=index, time_ns=int(part["time_ns"]), state=part[Topic.STATE],
        boxes=part[Topic.BOXES]["boxes"], onions=part[Topic.ONIONS]["onions"],
        color_jpeg=part[Topic.COLOR], depth_raw=depth, depth_shape=shape,
        inspection_png=part.get(Topic.INSPECTION),
    )


def read_demonstrations(paths: Sequence[str | Path], *, recover: bool = False
                        ) -> list[Demonstration]:
    """One ground-truth :class:`~irl.demonstrations.Demonstration` per session file."""
    return [open_session(p, recover=recover).demonstration() for p in paths]
