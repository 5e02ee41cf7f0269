"""Write a session to MCAP, frame by frame, so an interruption loses nothing written.

A frame's sensor side (colour, depth where the sensor has it, calibration, the step clock,
the inspection view) is written by :meth:`SessionWriter.write_sensor_frame`; a simulated frame
adds its ground truth with :meth:`SessionWriter.write_frame`. A robot's sorting run adds each
step's decision and running counts with :meth:`SessionWriter.write_decision`. See
:mod:`recordings.session.schema`.

Every frame's messages go into their own zstd chunk that is flushed to the OS before the next
frame is rendered (:meth:`mcap.writer.Writer.flush`). A process killed outright (SIGKILL, power
loss after the OS wrote the pages) leaves a file without its summary whose every complete chunk
is readable with ``recordings.open_session(path, recover=True)``; a recording stopped by an
exception or Ctrl-C is finished normally (summary, footer) with status ``interrupted``.

SIGINT and SIGTERM are held while a frame, a decision or the file's end is being written, and
delivered once it is whole: a signal that lands in the middle of a write would raise inside it
and leave half a record in the file, with the summary written after it.
"""

from __future__ import annotations

import functools
import json
import logging
import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Protocol, TypeVar

import numpy as np
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations
from foxglove_schemas_protobuf.PointsAnnotation_pb2 import PointsAnnotation
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from mcap.writer import CompressionType, Writer
from mcap_protobuf.schema import build_file_descriptor_set

from irl.domains.onion_sorting import SORTING_TASK
from irl.domains.task import TaskDescription
from recordings.session.frames import TruthFrame
from recordings.session.schema import (
    CLASS_COLORS,
    CLASS_NAMES,
    END_METADATA,
    EVALUATION_JSON_SCHEMAS,
    FORMAT_NAME,
    FORMAT_VERSION,
    JSON_SCHEMAS,
    ROBOT_METADATA,
    SENSOR_JSON_SCHEMAS,
    SESSION_METADATA,
    Topic,
    check_task,
    json_schema_bytes,
)
from recordings.session.urdf import UrdfJoints
from recordings.session.world import (
    World,
    frame_transforms,
    joint_states,
    robot_record,
    scene_update,
)

__all__ = [
    "EncodedImage",
    "SessionWriter",
    "SortingDecision",
    "box_annotations",
    "calibration_message",
    "encode_color",
    "encode_depth",
]

logger = logging.getLogger(__name__)

_PROTO_TOPICS = {
    Topic.COLOR: CompressedImage, Topic.DEPTH: RawImage, Topic.CALIBRATION: CameraCalibration,
    Topic.INSPECTION: CompressedImage, Topic.INSPECTION_CALIBRATION: CameraCalibration,
    Topic.ANNOTATIONS: ImageAnnotations,
}
_RGBA = {k: (*(c / 255.0 for c in rgb), 1.0) for k, rgb in CLASS_COLORS.items()}
#: Keys of a ``/ground_truth/state`` message besides the task's factors (which sit between
#: ``state`` and ``action``); a factor may not take one of these names.
_STATE_KEYS = ("frame", "step", "phase", "time_s", "state", "action", "occluded",
               "occluded_fraction")
#: The factor of the task whose values a decision's ``perceived`` holds.
_PERCEIVED_FACTOR = "prediction"


class SortingDecision(Protocol):
    """One step of a robot's sorting run, as :meth:`SessionWriter.write_decision` reads it
    (``robot.evaluation.EvaluationStep`` satisfies it).

    ``state``, ``action`` and ``next_state`` are flat indices of the session's task; ``onion``
    the line-up index of the onion in focus after the step, ``blemished`` its true class;
    ``perceived`` the classifier's answer (a value index of the task's ``prediction`` factor)
    if the step inspected it; ``fate`` (``"bin"`` or ``"line"``) if the step decided it;
    ``tp`` .. ``recall`` running over the onions decided so far. A decision may also carry
    ``p_blemished`` and ``view_p_blemished`` (the inspection's fused and per-view
    probabilities); they are written where present.
    """

    @property
    def step(self) -> int: ...
    @property
    def state(self) -> int: ...
    @property
    def action(self) -> int: ...
    @property
    def next_state(self) -> int: ...
    @property
    def onion(self) -> int | None: ...
    @property
    def blemished(self) -> bool | None: ...
    @property
    def perceived(self) -> int | None: ...
    @property
    def fate(self) -> str | None: ...
    @property
    def tp(self) -> int: ...
    @property
    def fp(self) -> int: ...
    @property
    def tn(self) -> int: ...
    @property
    def fn(self) -> int: ...
    @property
    def precision(self) -> float: ...
    @property
    def recall(self) -> float: ...


_HELD_SIGNALS = frozenset({signal.SIGINT, signal.SIGTERM})
_F = TypeVar("_F", bound=Callable[..., Any])


@contextmanager
def _signals_held() -> Iterator[None]:
    """Hold SIGINT and SIGTERM until the block ends; a signal that arrives meanwhile goes to its
    own handler (Ctrl-C raises ``KeyboardInterrupt``) after it.

    The handlers are swapped, not the signal mask: a process with other threads (the renderer's,
    torch's) takes a masked signal on one of them, and Python then runs the handler in the
    main thread all the same. Python runs handlers only in the main thread, so a block running
    in any other thread is never interrupted by one and holds nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[tuple[int, Any]] = []
    previous = {sig: signal.getsignal(sig) for sig in _HELD_SIGNALS}
    previous = {sig: h for sig, h in previous.items() if h is not None}  # not set from Python
    for sig in previous:
        signal.signal(sig, lambda signum, frame: caught.append((signum, frame)))
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        for signum, frame in caught:
            handler = previous[signum]
            if callable(handler):
                handler(signum, frame)
            elif handler == signal.SIG_DFL:
                signal.raise_signal(signum)


def _whole(method: _F) -> _F:
    """Run ``method`` with SIGINT and SIGTERM held (:func:`_signals_held`): what it writes to the
    file is whole when an interruption arrives."""
    @functools.wraps(method)
    def held(*args, **kwargs):
        with _signals_held():
            return method(*args, **kwargs)
    return held  # type: ignore[return-value]


def _stamp(msg, time_ns: int) -> None:
    msg.timestamp.seconds, msg.timestamp.nanos = divmod(int(time_ns), 1_000_000_000)


def encode_color(rgb: np.ndarray, fmt: str = "jpeg", quality: int = 90) -> bytes:
    """Compress ``rgb`` (H, W, 3) uint8 to JPEG or PNG bytes."""
    import cv2

    if fmt not in ("jpeg", "png"):
        raise ValueError(f"fmt must be 'jpeg' or 'png'; got {fmt!r}")
    params = [cv2.IMWRITE_JPEG_QUALITY, quality] if fmt == "jpeg" else []
    ok, buf = cv2.imencode(".jpg" if fmt == "jpeg" else ".png",
                           np.ascontiguousarray(rgb[..., ::-1]), params)
    if not ok:
        raise ValueError(f"could not encode an image of shape {rgb.shape} as {fmt}")
    return buf.tobytes()


@dataclass(frozen=True)
class EncodedImage:
    """An image compressed already, written to the session as it is (a JPEG a camera or a bag
    gave, say, or a PNG that keeps its pixels exactly): no second lossy encoding.

    Attributes
    ----------
    format : str
        ``"jpeg"`` or ``"png"``.
    data : bytes
        The compressed image, colour or grey (read back as RGB).
    width, height : int
        Its size in pixels.
    """

    format: str
    data: bytes = field(repr=False)
    width: int
    height: int

    def __post_init__(self) -> None:
        if self.format not in ("jpeg", "png"):
            raise ValueError(f"format must be 'jpeg' or 'png'; got {self.format!r}")
        if self.width < 1 or self.height < 1:
            raise ValueError(f"an image must be at least 1x1; got {self.width}x{self.height}")


def _compressed(image: np.ndarray | EncodedImage, fmt: str) -> tuple[int, int, str, bytes]:
    """``(height, width, format, data)`` of ``image``: an :class:`EncodedImage` as it is, an
    RGB array compressed as ``fmt``."""
    if isinstance(image, EncodedImage):
        return image.height, image.width, image.format, image.data
    return image.shape[0], image.shape[1], fmt, encode_color(image, fmt)


def encode_depth(depth: np.ndarray) -> bytes:
    """Depth (H, W) float metres as 16UC1 little-endian millimetres (0 = no reading)."""
    mm = np.clip(np.round(np.asarray(depth, float) * 1000.0), 0, 65535).astype("<u2")
    return mm.tobytes()


def calibration_message(K: np.ndarray, width: int, height: int, frame_id: str,
                        time_ns: int) -> CameraCalibration:
    """A foxglove.CameraCalibration of an undistorted pinhole camera ``K`` (3, 3)."""
    msg = CameraCalibration(frame_id=frame_id, width=width, height=height,
                            distortion_model="plumb_bob")
    _stamp(msg, time_ns)
    msg.D.extend([0.0] * 5)
    msg.K.extend(np.asarray(K, float).ravel().tolist())
    msg.R.extend([1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0])
    P = np.zeros((3, 4))
    P[:, :3] = K
    msg.P.extend(P.ravel().tolist())
    return msg


def box_annotations(boxes: list[tuple[int, int, int, int, int]], time_ns: int
                    ) -> ImageAnnotations:
    """foxglove.ImageAnnotations outlining ``(x_min, y_min, x_max, y_max, class_id)`` boxes."""
    msg = ImageAnnotations()
    for x0, y0, x1, y1, cid in boxes:
        box = msg.points.add(type=PointsAnnotation.LINE_LOOP, thickness=1.5)
        _stamp(box, time_ns)
        for x, y in ((x0, y0), (x1, y0), (x1, y1), (x0, y1)):
            box.points.add(x=float(x), y=float(y))
        r, g, b, a = _RGBA[cid]
        box.outline_color.r, box.outline_color.g, box.outline_color.b = r, g, b
        box.outline_color.a = a
        text = msg.texts.add(text=CLASS_NAMES[cid], font_size=9.0)
        _stamp(text, time_ns)
        text.position.x, text.position.y = float(x0), float(max(y0 - 2, 0))
        text.text_color.r, text.text_color.g, text.text_color.b, text.text_color.a = r, g, b, a
    return msg


def _action_name(task: TaskDescription, action: int) -> str:
    """The name of action index ``action`` of ``task``; ValueError outside ``[0, A)``."""
    if not 0 <= int(action) < task.n_actions:
        raise ValueError(f"action must be in [0, {task.n_actions}) for task {task.name!r}; "
                         f"got {action}")
    return task.action_names[int(action)]


class SessionWriter:
    """Writes one session's MCAP file; use as a context manager.

    Parameters
    ----------
    path : path-like
        The ``.mcap`` file to create (an existing file is refused unless ``overwrite``).
    metadata : dict
        Session description: seed, configuration, ... (stored as JSON strings in the
        ``onionsort.session`` metadata record with the format name and version).
    camera_K : ndarray of shape (3, 3)
        Intrinsics of the main camera.
    inspection_K : ndarray of shape (3, 3) or None
        Intrinsics of the inspection view; None for a sensor without one.
    frames_per_step : int
        Frames of each step (phases ``0 .. frames_per_step - 1``).
    depth : bool
        Whether the main camera gives depth (a plain video does not).
    ground_truth : bool
        Whether frames come with ground truth (:meth:`write_frame`) or not
        (:meth:`write_sensor_frame` only).
    overwrite : bool
    task : TaskDescription
        The task the steps belong to: the names of the ground-truth states and actions, and the
        encoding of the step's ``state`` and ``action``. Stored (``task.to_dict()``) in the
        session record under ``"task"``; the onion-sorting task by default.
    """

    def __init__(self, path: str | Path, metadata: dict[str, Any], camera_K: np.ndarray,
                 inspection_K: np.ndarray | None = None, *, frames_per_step: int,
                 depth: bool = True, ground_truth: bool = True,
                 overwrite: bool = False, task: TaskDescription = SORTING_TASK) -> None:
        self.path = Path(path)
        if self.path.exists() and not overwrite:
            raise FileExistsError(f"{self.path} exists; choose another --out or remove it")
        if int(frames_per_step) < 1:
            raise ValueError(f"frames_per_step must be >= 1; got {frames_per_step}")
        check_task(task, _STATE_KEYS, "a ground-truth state message")
        if "task" in metadata:
            raise ValueError("metadata must not hold 'task'; pass the task as task=")
        self.task = task
        self.metadata = dict(metadata)
        self.camera_K = np.asarray(camera_K, float)
        self.inspection_K = None if inspection_K is None else np.asarray(inspection_K, float)
        self.frames_per_step = int(frames_per_step)
        self.depth, self.ground_truth = bool(depth), bool(ground_truth)
        self.n_frames = 0
        self.n_steps = 0
        #: Log a warning when the file is finished as interrupted; False for a temporary file
        #: its caller removes on failure (an import's ``.partial``).
        self.report_interruption = True
        self._file = None
        self._writer: Writer | None = None
        self._channels: dict[str, int] = {}
        self._kinematics: dict[Path, UrdfJoints] = {}

    @_whole
    def __enter__(self) -> SessionWriter:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        # the header, the session record and the channels go to a temporary name first, so the
        # file's own name never holds a file without them (killed at once, nothing is left but
        # the temporary); after the rename, frames follow into the same open file
        tmp = self.path.with_name(self.path.name + ".partial")
        self._file = tmp.open("wb")
        try:
            self._start()
            tmp.replace(self.path)
        except BaseException:
            self._file.close()
            self._writer, self._file = None, None
            tmp.unlink(missing_ok=True)
            raise
        return self

    def _start(self) -> None:
        self._writer = Writer(self._file, chunk_size=4 * 1024 * 1024,
                              compression=CompressionType.ZSTD, enable_crcs=True)
        self._writer.start(profile="", library=f"onionsort/{self.metadata.get('software', '')}")
        record = {"format": FORMAT_NAME, "format_version": FORMAT_VERSION,
                  "created_utc": datetime.now(UTC).isoformat(timespec="seconds")}
        record.update({k: v if isinstance(v, str) else json.dumps(v, sort_keys=True)
                       for k, v in self.metadata.items()})
        record["frames_per_step"] = str(self.frames_per_step)
        record["sensors"] = json.dumps({"depth": self.depth,
                                        "inspection": self.inspection_K is not None})
        record["ground_truth"] = json.dumps(self.ground_truth)
        record["camera_K"] = json.dumps(self.camera_K.tolist())
        record["task"] = json.dumps(self.task.to_dict(), sort_keys=True)
        if self.inspection_K is not None:
            record["inspection_K"] = json.dumps(self.inspection_K.tolist())
        self._writer.add_metadata(SESSION_METADATA, record)
        for topic, cls in _PROTO_TOPICS.items():
            if not self._has(topic):
                continue
            schema = self._writer.register_schema(
                cls.DESCRIPTOR.full_name, "protobuf",
                build_file_descriptor_set(cls).SerializeToString())
            self._channels[topic] = self._writer.register_channel(topic, "protobuf", schema)
        json_topics = {**SENSOR_JSON_SCHEMAS, **(JSON_SCHEMAS if self.ground_truth else {})}
        for topic, (name, schema) in json_topics.items():
            sid = self._writer.register_schema(name, "jsonschema", json_schema_bytes(schema))
            self._channels[topic] = self._writer.register_channel(topic, "json", sid)
        self._writer.flush()

    def _has(self, topic: str) -> bool:
        if topic == Topic.DEPTH:
            return self.depth
        if topic in (Topic.INSPECTION, Topic.INSPECTION_CALIBRATION):
            return self.inspection_K is not None
        return self.ground_truth or topic not in Topic.GROUND_TRUTH

    @_whole
    def __exit__(self, exc_type, exc, tb) -> None:
        status = "complete" if exc_type is None else "interrupted"
        self.close(status)

    @_whole
    def close(self, status: str = "complete") -> None:
        """Finish the file (summary, footer) with the end record's ``status``; idempotent."""
        if self._writer is None:
            return
        try:
            self._writer.add_metadata(END_METADATA, {
                "status": status, "n_frames": str(self.n_frames), "n_steps": str(self.n_steps)})
            self._writer.finish()
        finally:
            self._file.close()
            self._writer, self._file = None, None
        if status != "complete" and self.report_interruption:
            logger.warning("%s: recording %s after %d frames (%d steps); the file is finished "
                           "and readable", self.path, status, self.n_frames, self.n_steps)

    def _write(self, topic: str, payload: bytes, time_ns: int, sequence: int) -> None:
        self._writer.add_message(self._channels[topic], log_time=time_ns, data=payload,
                                 publish_time=time_ns, sequence=sequence)

    def _write_json(self, topic: str, obj: dict, time_ns: int, sequence: int) -> None:
        if topic not in self._channels:  # an optional topic: registered on first use
            name, schema = EVALUATION_JSON_SCHEMAS[topic]
            sid = self._writer.register_schema(name, "jsonschema", json_schema_bytes(schema))
            self._channels[topic] = self._writer.register_channel(topic, "json", sid)
        self._write(topic, json.dumps(obj, separators=(",", ":")).encode(), time_ns, sequence)

    @_whole
    def write_decision(self, decision: SortingDecision, *, frame: int, time_ns: int) -> None:
        """Write one step of a robot's sorting run and flush it to the OS.

        ``/evaluation/decision`` (what the robot did and perceived) always, and in a session
        with ground truth ``/evaluation/counts`` (the running TP/FP/TN/FN, precision and
        recall after the step); both with ``sequence`` the step number. ``frame`` is the index
        of the step's first frame and ``time_ns`` its time. The channels are registered on
        first use: a session without a robot's run has none of them.

        Raises
        ------
        ValueError
            If the decision's action or states are not indices of the session's task, or its
            ``fate`` is not ``"bin"``, ``"line"`` or None.
        """
        if self._writer is None:
            raise RuntimeError("SessionWriter must be entered (`with SessionWriter(...)`)")
        task, step = self.task, int(decision.step)
        fate = decision.fate
        if fate not in (None, "bin", "line"):
            raise ValueError(f"decision.fate must be 'bin', 'line' or None; got {fate!r} at "
                             f"step {step}")
        for name in ("state", "next_state"):
            s = int(getattr(decision, name))
            if not 0 <= s < task.n_states:
                raise ValueError(f"decision.{name} must be in [0, {task.n_states}) for task "
                                 f"{task.name!r}; got {s} at step {step}")
        perceived = decision.perceived
        if perceived is not None:
            perceived = (task.value_name(_PERCEIVED_FACTOR, int(perceived))
                         if _PERCEIVED_FACTOR in task.factor_names else str(int(perceived)))
        onion = None if decision.onion is None else int(decision.onion)
        self._write_json(Topic.DECISION, {
            "step": step, "frame": int(frame), "state": int(decision.state),
            "state_name": task.state_name(int(decision.state)),
            "action": int(decision.action), "action_name": _action_name(task, decision.action),
            "next_state": int(decision.next_state),
            "next_state_name": task.state_name(int(decision.next_state)),
            "onion": onion, "perceived": perceived, "fate": fate,
            **_inspection_fields(decision)}, time_ns, step)
        if self.ground_truth:
            counts = {k: int(getattr(decision, k)) for k in ("tp", "fp", "tn", "fn")}
            blemished = None if decision.blemished is None else bool(decision.blemished)
            self._write_json(Topic.COUNTS, {
                "step": step, "frame": int(frame), "onion": onion, "blemished": blemished,
                **counts, "decided": sum(counts.values()),
                "precision": float(decision.precision), "recall": float(decision.recall)},
                time_ns, step)
        self._writer.flush()

    @_whole
    def write_sensor_frame(self, *, index: int, step: int, phase: int, time_ns: int,
                           color: np.ndarray, depth: np.ndarray | None = None,
                           inspection: np.ndarray | None = None,
                           world: World | None = None) -> None:
        """Write one frame's sensor side and flush it to the OS.

        Parameters
        ----------
        index : int
            Frame number in the session (the messages' ``sequence``).
        step, phase : int
            The step clock: the frame's step and its position in the step.
        time_ns : int
            Recording time of the frame.
        color : ndarray of shape (H, W, 3) or EncodedImage
            uint8 RGB (written as JPEG), or an image compressed already (written as it is).
        depth : ndarray of shape (H, W) or None
            float metres; required exactly when the writer was made with ``depth=True``.
        inspection : ndarray of shape (h, w, 3) or EncodedImage or None
            The inspection view, on a step's first frame (an array is written as PNG).
        world : World or None
            A snapshot of the world the frame shows: its 3D topics are written too
            (:meth:`write_world`).
        """
        self._sensor_side(index, step, phase, time_ns, color, depth, inspection)
        if world is not None:
            self.write_world(world, time_ns, index)
        self._end_frame()

    @_whole
    def write_frame(self, frame: TruthFrame) -> None:
        """Write one simulated frame, sensor side and ground truth, and flush it to the OS.

        A frame that also has a ``world`` snapshot (``robot.world.WorldFrame``) gets its 3D
        topics written with it (:meth:`write_world`).
        """
        if not self.ground_truth:
            raise ValueError(f"{self.path} was opened with ground_truth=False; write its "
                             "frames with write_sensor_frame")
        t, i = round(frame.time_s * 1e9), frame.index
        self._sensor_side(i, frame.step.step, frame.phase, t, frame.color, frame.depth,
                          frame.inspection)
        self._truth_side(frame, t, i)
        world = getattr(frame, "world", None)
        if world is not None:
            self.write_world(world, t, i)
        self._end_frame()

    def _sensor_side(self, i, step, phase, t, color, depth, inspection) -> None:
        if self._writer is None:
            raise RuntimeError("SessionWriter must be entered (`with SessionWriter(...)`)")
        if (depth is not None) != self.depth:
            raise ValueError(f"{self.path}: this session was opened with depth={self.depth}; "
                             f"frame {i} {'has' if depth is not None else 'lacks'} depth")
        if not 0 <= phase < self.frames_per_step:
            raise ValueError(f"phase must be in [0, {self.frames_per_step}); got {phase}")
        h, w, fmt, data = _compressed(color, "jpeg")
        msg = CompressedImage(frame_id="camera", format=fmt, data=data)
        _stamp(msg, t)
        self._write(Topic.COLOR, msg.SerializeToString(), t, i)
        if depth is not None:
            msg = RawImage(frame_id="camera", width=w, height=h, encoding="16UC1", step=2 * w,
                           data=encode_depth(depth))
            _stamp(msg, t)
            self._write(Topic.DEPTH, msg.SerializeToString(), t, i)
        self._write(Topic.CALIBRATION,
                    calibration_message(self.camera_K, w, h, "camera", t).SerializeToString(),
                    t, i)
        self._write_json(Topic.STEP_CLOCK, {"frame": i, "step": int(step), "phase": int(phase)},
                         t, i)
        if inspection is not None and self.inspection_K is None:
            raise ValueError(f"{self.path}: frame {i} has an inspection view but the session "
                             "was opened without inspection_K (no inspection camera)")
        if inspection is not None:
            ih, iw, fmt, data = _compressed(inspection, "png")
            msg = CompressedImage(frame_id="inspection", format=fmt, data=data)
            _stamp(msg, t)
            self._write(Topic.INSPECTION, msg.SerializeToString(), t, i)
            self._write(Topic.INSPECTION_CALIBRATION, calibration_message(
                self.inspection_K, iw, ih, "inspection", t).SerializeToString(), t, i)
        if phase == 0:
            self.n_steps += 1

    @_whole
    def write_world(self, world: World, time_ns: int, sequence: int) -> None:
        """Write the 3D side of ``world`` at ``time_ns`` (see :mod:`recordings.session.world`).

        ``/tf`` (the cameras and a robot's links) and ``/joint_states`` (with a robot) always;
        ``/scene`` (the bodies, onions coloured by class) only in a session with ground truth.
        The first robot seen is described in the ``onionsort.robot`` metadata record. The
        channels are registered on first use: a session without a world has none of them.
        Call it between the frame's other messages and its end (:meth:`write_sensor_frame`
        and :meth:`write_frame` do); ``sequence`` is the frame's index.
        """
        if self._writer is None:
            raise RuntimeError("SessionWriter must be entered (`with SessionWriter(...)`)")
        robot = world.robot
        kinematics = None
        if robot is not None:
            urdf = Path(robot.urdf)
            kinematics = self._kinematics.get(urdf)
            if kinematics is None:
                kinematics = self._kinematics[urdf] = UrdfJoints(urdf)
                if len(self._kinematics) == 1:
                    self._writer.add_metadata(ROBOT_METADATA, robot_record(robot, kinematics))
        self._write_proto(Topic.TF, frame_transforms(world, time_ns, kinematics), time_ns,
                          sequence)
        if robot is not None:
            self._write_proto(Topic.JOINT_STATES, joint_states(robot, time_ns), time_ns,
                              sequence)
        if self.ground_truth and world.shapes:
            self._write_proto(Topic.SCENE, scene_update(world.shapes, time_ns), time_ns,
                              sequence)

    def _write_proto(self, topic: str, msg, time_ns: int, sequence: int) -> None:
        """Write protobuf ``msg`` on ``topic``, registering its schema and channel first if
        this is the topic's first message."""
        if topic not in self._channels:
            cls = type(msg)
            schema = self._writer.register_schema(
                cls.DESCRIPTOR.full_name, "protobuf",
                build_file_descriptor_set(cls).SerializeToString())
            self._channels[topic] = self._writer.register_channel(topic, "protobuf", schema)
        self._write(topic, msg.SerializeToString(), time_ns, sequence)

    def _end_frame(self) -> None:
        self._writer.flush()  # one chunk per frame, handed to the OS now
        self.n_frames += 1

    def _truth_side(self, frame: TruthFrame, t: int, i: int) -> None:
        step, task = frame.step, self.task
        if frame.phase == 0:
            self._write_json(Topic.ACTION, {
                "step": step.step, "frame": i, "state": step.state, "action": step.action,
                "action_name": _action_name(task, step.action),
                "next_state": step.next_state, "occluded": step.occluded}, t, step.step)
        factors = {f: task.value_name(f, v) for f, v in task.decode(step.state).items()}
        self._write_json(Topic.STATE, {
            "frame": i, "step": step.step, "phase": frame.phase, "time_s": frame.time_s,
            "state": step.state, **factors,
            "action": step.action, "occluded": step.occluded,
            "occluded_fraction": round(frame.occluded_fraction, 5)}, t, i)
        self._write_json(Topic.BOXES, {"frame": i, "boxes": [
            {"onion_id": o.onion_id, "class_id": int(o.blemished),
             "label": CLASS_NAMES[int(o.blemished)], "x_min": o.box[0], "y_min": o.box[1],
             "x_max": o.box[2], "y_max": o.box[3], "visible_pixels": o.visible_pixels}
            for o in frame.onions if o.box is not None]}, t, i)
        self._write(Topic.ANNOTATIONS, box_annotations(
            [(*o.box, int(o.blemished)) for o in frame.onions if o.box is not None], t,
        ).SerializeToString(), t, i)
        self._write_json(Topic.ONIONS, {"frame": i, "onions": [
            {"onion_id": o.onion_id, "blemished": o.blemished, "in_focus": o.in_focus,
             "position": [round(float(x), 5) for x in o.position]}
            for o in frame.onions]}, t, i)


def _inspection_fields(decision) -> dict:
    """The inspection's probabilities a decision carries, if any: ``p_blemished`` (fused) and
    ``view_p_blemished`` (per view, None where no onion was found)."""
    p_bad = getattr(decision, "p_blemished", None)
    if p_bad is None:
        return {}
    per_view = getattr(decision, "view_p_blemished", ()) or ()
    return {"p_blemished": round(float(p_bad), 5),
            "view_p_blemished": [None if v is None else round(float(v), 5) for v in per_view]}
