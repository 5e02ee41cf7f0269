"""Read a session back: its frames, its steps, and its demonstration for ``irl``.

The sensor side is all a session needs: every frame with its colour image (depth and the
inspection view where the sensor has them) and its step clock. Ground truth is read where the
file has it and is ``None`` elsewhere (a session imported from a camera or a video).

A robot's sorting run (``onionsort evaluate``) adds each step's decision and, with ground
truth, the running TP/FP/TN/FN (:attr:`Session.decisions`, :attr:`Session.sorting_counts`).

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

from irl.demonstrations import Demonstration, StepTruth, Trajectory
from irl.domains.onion_sorting import SORTING_TASK
from irl.domains.task import TaskDescription
from recordings.session.schema import (
    END_METADATA,
    FORMAT_NAME,
    PERCEPTION_METADATA,
    READABLE_VERSIONS,
    ROBOT_METADATA,
    SESSION_METADATA,
    PerceptionTopic,
    Topic,
    task_of,
)
from recordings.session.steps import group_steps
from recordings.session.world import (
    SceneItem,
    Transform,
    read_joint_states,
    read_scene,
    read_transforms,
)

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
    """One recorded frame: its images (decoded on demand), its step clock, its ground truth.

    ``step`` and ``phase`` come from the sensor side's step clock. ``state`` holds the
    ``/ground_truth/state`` message, ``boxes`` and ``onions`` the lists of the
    ``/ground_truth/boxes`` and ``/ground_truth/onions`` messages: each is None in a session
    without ground truth.

    The 3D side (:mod:`recordings.session.world`), None where the file has none: ``transforms`` the
    ``/tf`` transforms by child frame, ``(parent, translation (3,), rotation (4,) xyzw)``;
    ``joints`` the ``/joint_states`` positions by joint name; ``scene`` the ``/scene``
    entities (ground truth).
    """

    index: int
    time_ns: int
    step: int
    phase: int
    color_jpeg: bytes = field(repr=False)
    depth_raw: bytes | None = field(default=None, repr=False)
    depth_shape: tuple[int, int] = (0, 0)
    inspection_png: bytes | None = field(default=None, repr=False)
    state: dict | None = None
    boxes: list[dict] | None = None
    onions: list[dict] | None = None
    transforms: dict[str, Transform] | None = field(default=None, repr=False)
    joints: dict[str, float] | None = field(default=None, repr=False)
    scene: list[SceneItem] | None = field(default=None, repr=False)

    @property
    def occluded(self) -> bool | None:
        """Whether the step was truly occluded (ground truth), None without ground truth."""
        return None if self.state is None else bool(self.state["occluded"])

    @property
    def color(self) -> np.ndarray:
        """The main camera's image, (H, W, 3) uint8 RGB."""
        return _decode_image(self.color_jpeg)

    @property
    def depth(self) -> np.ndarray | None:
        """Depth in metres, (H, W) float32 (0 where there was no reading); None without a
        depth sensor."""
        if self.depth_raw is None:
            return None
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
    frames_per_step : int
        Frames of each step.
    has_depth, has_inspection, has_ground_truth : bool
        Whether the sensor gave depth, whether there was an inspection view, and whether the
        file carries ground truth.
    steps : list of StepTruth
        The ground-truth steps, in order; empty without ground truth.
    problem : str or None
        What was wrong with a damaged file.
    perception : dict of int -> dict
        The ``/perception/state`` message of each perceived step (empty if the session was
        not perceived; see :mod:`recordings.session.perception`).
    perception_models : dict or None
        The ``onionsort.perception`` record: which models perceived the session.
    task : TaskDescription
        The task of the session's states and actions: the session record's ``"task"``, or the
        onion-sorting task in files that predate the field.
    robot : dict or None
        The ``onionsort.robot`` record of a session whose world has a robot (``name``,
        ``urdf``, ``root_link``, ``joints``); None otherwise.
    decisions : dict of int -> dict
        The ``/evaluation/decision`` message of each step of a robot's sorting run (the action,
        states, the onion in focus, what was perceived, the fate); empty in other sessions.
    sorting_counts : dict of int -> dict
        The ``/evaluation/counts`` message of each step (running ``tp``, ``fp``, ``tn``,
        ``fn``, ``precision``, ``recall``); empty without a robot's run or ground truth.
    """

    path: Path
    metadata: dict
    status: str
    frames_per_step: int
    has_depth: bool
    has_inspection: bool
    has_ground_truth: bool
    steps: list[StepTruth]
    _frames: list[FrameRecord] = field(repr=False)
    problem: str | None = None
    perception: dict[int, dict] = field(default_factory=dict, repr=False)
    perception_models: dict | None = None
    task: TaskDescription = SORTING_TASK
    robot: dict | None = None
    decisions: dict[int, dict] = field(default_factory=dict, repr=False)
    sorting_counts: dict[int, dict] = field(default_factory=dict, repr=False)

    def __len__(self) -> int:
        return len(self._frames)

    @property
    def n_frames(self) -> int:
        return len(self._frames)

    def frames(self) -> Iterator[FrameRecord]:
        """Every sensor frame in order, with its ground truth where the file has it."""
        return iter(self._frames)

    def step_frames(self) -> list[list[FrameRecord]]:
        """The frames of each complete step, steps in order, frames in phase order.

        A session ends with a complete step unless it was interrupted or damaged; an
        incomplete last step is left out. Steps must be numbered ``0, 1, ...``.

        Raises
        ------
        ValueError
            If a step other than the last is incomplete, or the numbering has a gap.
        """
        steps = group_steps(self._frames, step=lambda f: f.step, phase=lambda f: f.phase,
                            frames_per_step=self.frames_per_step, incomplete="drop",
                            source=str(self.path))
        numbers = [k for k, _ in steps]
        last = max((f.step for f in self._frames), default=-1)
        expected = list(range(last + 1))
        if numbers != expected and numbers != expected[:-1]:
            missing = sorted(set(expected) - set(numbers))
            raise ValueError(f"{self.path}: steps {missing[:5]} are incomplete or missing; a "
                             f"session's steps must be 0..T-1 of {self.frames_per_step} "
                             "frames each")
        return [frames for _, frames in steps]

    def trajectory(self) -> Trajectory:
        """Ground-truth states and actions of the steps, shape (T,) each."""
        self._require_ground_truth()
        return Trajectory(states=np.array([s.state for s in self.steps], np.int64),
                          actions=np.array([s.action for s in self.steps], np.int64))

    @property
    def occluded(self) -> np.ndarray:
        """Which steps the passer-by occluded (ground truth), bool (T,)."""
        self._require_ground_truth()
        return np.array([s.occluded for s in self.steps], bool)

    def _require_ground_truth(self) -> None:
        if not self.has_ground_truth:
            raise ValueError(f"{self.path} carries no ground truth (a sensor-only session); "
                             "use perceived_demonstration() after `onionsort perceive`")
        if not self.steps:
            raise ValueError(f"{self.path}: the session holds no complete step")

    def demonstration(self) -> Demonstration:
        """The session as a demonstration of ``(s, a)`` pairs from ground truth.

        Observation ``o = task.pair(s, a) = s * A + a`` (the identity observation model of
        :meth:`irl.demonstrations.Demonstration.from_pairs`), None at occluded steps.
        """
        traj, task = self.trajectory(), self.task
        return Demonstration([None if occluded else task.pair(int(s), int(a))
                              for s, a, occluded in zip(traj.states, traj.actions,
                                                        self.occluded, strict=True)])

    def perceived_demonstration(self) -> Demonstration:
        """The session as perception saw it: pair observations ``o = s * A + a`` of the
        perceived state and action, None exactly where the classifier said occluded.

        Uses only the sensor side and the perception topics, never ground truth.

        Raises
        ------
        ValueError
            If the session has no perception topics (run ``onionsort perceive`` on it), or its
            perceived steps are not numbered ``0..T-1``.
        """
        if not self.perception:
            raise ValueError(f"{self.path} has no perception topics; run `onionsort perceive "
                             f"{self.path}` first")
        numbers = sorted(self.perception)
        if numbers != list(range(len(numbers))):
            raise ValueError(f"{self.path}: perceived steps must be numbered 0..T-1; got "
                             f"{numbers[:5]}... (perceive it again with --replace)")
        return Demonstration([self.perception[t]["observation"] for t in numbers])


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
    steps: dict[int, StepTruth] = {}
    perception: dict[int, dict] = {}
    evaluation: dict[str, dict[int, dict]] = {Topic.DECISION: {}, Topic.COUNTS: {}}
    models = None
    robot = None
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
                elif name == ROBOT_METADATA:
                    robot = _decode_metadata(dict(rec.metadata))
                continue
            if meta is None:
                break  # a session's metadata precedes every message
            if name == PerceptionTopic.STATE:
                msg = json.loads(rec.data)
                perception[int(msg["step"])] = msg
                continue
            if name in evaluation:
                msg = json.loads(rec.data)
                evaluation[name][int(msg["step"])] = msg
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
    metadata = _decode_metadata(meta)
    version = str(metadata.get("format_version"))
    if version not in READABLE_VERSIONS:
        raise NotASessionError(f"{path} is an onionsort session of format version {version!r}; "
                               f"this version of onionsort reads {READABLE_VERSIONS}")
    layout = _layout(metadata, version, path)
    task = _task(metadata, path)
    frames = [_assemble(i, parts[i], version) for i in sorted(parts)
              if _complete(parts[i], version, layout["depth"])]
    truth = version == "1" or bool(metadata.get("ground_truth", False))
    fps = layout["frames_per_step"]
    phases: dict[int, set[int]] = {}
    for f in frames:
        phases.setdefault(f.step, set()).add(f.phase)
    whole = {t for t, seen in phases.items() if fps and len(seen) == fps}
    # ground truth only for the steps whose frames are all there (an interrupted or damaged
    # recording may end in the middle of one)
    complete_steps = [steps[t] for t in sorted(steps) if t in whole]
    if problem is None and end is None:
        problem = "no end record"
    status = "damaged" if problem else end.get("status", "complete")
    if problem:
        message = (
            f"{path} is truncated or corrupt ({problem}); recovered {len(frames)} complete "
            f"frames and {len(whole)} complete steps from {path.stat().st_size} bytes")
        if not recover:
            raise RecordingDamagedError(message + "; open it with recover=True to use them")
        logger.warning("%s", message)
    return Session(path=path, metadata=metadata, status=status,
                   frames_per_step=layout["frames_per_step"], has_depth=layout["depth"],
                   has_inspection=layout["inspection"],
                   has_ground_truth=truth, steps=complete_steps, _frames=frames,
                   problem=problem, perception=perception, perception_models=models,
                   task=task, robot=robot, decisions=evaluation[Topic.DECISION],
                   sorting_counts=evaluation[Topic.COUNTS])


def _task(metadata: dict, path: Path) -> TaskDescription:
    """The session record's task, or the onion-sorting task for files without one."""
    return task_of(metadata, f"{path}: the session record", NotASessionError)


def _layout(metadata: dict, version: str, path: Path) -> dict:
    """Frames per step and whether there are depth and an inspection view, from the session
    record."""
    if version == "1":  # simulated, always with depth; frames per step in its configuration
        fps = metadata.get("config", {}).get("frames_per_step")
        return {"frames_per_step": int(fps) if fps else 0, "depth": True, "inspection": True}
    try:
        fps = int(metadata["frames_per_step"])
        depth = bool(metadata["sensors"]["depth"])
        inspection = bool(metadata["sensors"].get("inspection", False))
    except (KeyError, TypeError, ValueError) as exc:
        raise NotASessionError(f"{path}: the session record lacks {exc} (frames_per_step, "
                               "sensors.depth)") from None
    return {"frames_per_step": fps, "depth": depth, "inspection": inspection}


def _decode_metadata(meta: dict) -> dict:
    out = {}
    for k, v in meta.items():
        try:
            out[k] = json.loads(v)
        except (json.JSONDecodeError, TypeError):
            out[k] = v
    return out


def _collect(topic: str, rec: Message, parts: dict[int, dict], steps: dict[int, StepTruth]):
    if topic == Topic.ACTION:
        m = json.loads(rec.data)
        steps[int(m["step"])] = StepTruth(step=int(m["step"]), state=int(m["state"]),
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
    elif topic in (Topic.STEP_CLOCK, Topic.STATE, Topic.BOXES, Topic.ONIONS):
        part[topic] = json.loads(rec.data)
    elif topic == Topic.TF:
        part[topic] = read_transforms(rec.data)
    elif topic == Topic.JOINT_STATES:
        part[topic] = read_joint_states(rec.data)
    elif topic == Topic.SCENE:
        part[topic] = read_scene(rec.data)


def _clock_topic(version: str) -> str:
    """Where a frame's step and phase are: the step clock, or in version 1 the ground truth."""
    return Topic.STATE if version == "1" else Topic.STEP_CLOCK


def _complete(part: dict, version: str, depth: bool) -> bool:
    need = [Topic.COLOR, _clock_topic(version)] + ([Topic.DEPTH] if depth else [])
    if version == "1":
        need += [Topic.BOXES, Topic.ONIONS]
    return all(t in part for t in need)


def _assemble(index: int, part: dict, version: str) -> FrameRecord:
    clock = part[_clock_topic(version)]
    depth, shape = part.get(Topic.DEPTH, (None, (0, 0)))
    boxes, onions = part.get(Topic.BOXES), part.get(Topic.ONIONS)
    return FrameRecord(
        index=index, time_ns=int(part["time_ns"]), step=int(clock["step"]),
        phase=int(clock.get("phase", 0)), color_jpeg=part[Topic.COLOR], depth_raw=depth,
        depth_shape=shape, inspection_png=part.get(Topic.INSPECTION),
        state=part.get(Topic.STATE), boxes=None if boxes is None else boxes["boxes"],
        onions=None if onions is None else onions["onions"], transforms=part.get(Topic.TF),
        joints=part.get(Topic.JOINT_STATES), scene=part.get(Topic.SCENE),
    )


def read_demonstrations(paths: Sequence[str | Path], *, recover: bool = False
                        ) -> list[Demonstration]:
    """One ground-truth :class:`~irl.demonstrations.Demonstration` per session file."""
    return [open_session(p, recover=recover).demonstration() for p in paths]
