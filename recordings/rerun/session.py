"""Log recorded sessions to Rerun under the entity root ``record/``.

Only what a session has is logged: colour always, depth where the sensor gave it, the
inspection view where there is one, and the ground-truth side only in a session that carries
it. A perceived session's perception topics are logged too, under ``perceive/``
(:mod:`recordings.rerun.perceive`). Entity paths::

    record/camera                    Pinhole (static): the main camera's intrinsics
    record/camera/color              EncodedImage (JPEG), every frame
    record/camera/depth              DepthImage (uint16 millimetres, meter=1000), with depth;
                                     0 (no point) beyond the work cell (``max_depth``)
    record/camera/color/truth_boxes  Boxes2D (XYXY, class_ids), with ground truth
    record/inspection                EncodedImage (PNG), on a step's first frame
    record/session                   TextDocument: which session is playing
    record/truth/state               TextDocument: the true state, action, occlusion per frame
    record/truth/factors/*           Scalars per step: each state factor of the session's task
                                     (onion, end_effector, prediction), and action
    record/truth/occlusion/*         Scalars per step: fraction (largest view fraction covered
                                     in the step), occluded (0/1)

The work cell in 3D (:mod:`recordings.rerun.world`), from the session's 3D topics where it has
them: ``record`` is the world (z up); ``record/camera`` and ``record/inspection`` are placed by
``/tf`` (the inspection view is a pinhole too, so both images show in their frustums);
``record/scene/*`` holds the bodies of ``/scene`` (belt, bin, gate, sorter, passer-by, onions in
the colours of their true classes); a session with a robot shows it from its URDF under
``record/robot``, its joints animated at every frame from ``/joint_states``. The blueprint
(:func:`session_blueprint`, sent when the logger closes) has a view only for what the sessions
hold; its 3D view holds the bodies, the robot and the pinhole cameras, the depth cloud hidden at
first where there are bodies or a robot.

Timelines: ``frame`` and ``step`` (both counted across every session logged to the stream) and
``time`` (the recording time of a frame, a duration). Series are sent whole, one
``send_columns`` call per series and session, on all three timelines (a step at its first
frame); their names, with the labels of the values, are logged static once.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
import rerun.urdf as rru

from irl.domains.onion_sorting import SORTING_TASK
from irl.domains.task import TaskDescription
from recordings.rerun.common import (
    WORK_CELL_DEPTH_M,
    close_recording,
    factor_values,
    log_camera_images,
    log_class_annotations,
    log_pinhole,
    log_series_names,
    open_recording,
    send_layout,
    send_series,
    value_labels,
)
from recordings.rerun.perceive import PerceptionLogger, perception_views
from recordings.rerun.world import WorldLogger, world_view
from recordings.session.reader import FrameRecord, Session
from recordings.session.world import WORLD_FRAME

__all__ = ["RECORD_ROOT", "SessionLogger", "session_blueprint"]

logger = logging.getLogger(__name__)

RECORD_ROOT = "record"
_TRUTH = f"{RECORD_ROOT}/truth"
#: The entity of each camera ``frame_id`` of ``/tf``.
_CAMERA_ENTITIES = {"camera": f"{RECORD_ROOT}/camera", "inspection": f"{RECORD_ROOT}/inspection"}


def session_blueprint(*, camera_pinhole: bool = True, depth: bool = True,
                      inspection: bool = True, inspection_pinhole: bool = True,
                      true_state: bool = True, truth_series: bool = True,
                      perception: bool = True, perceived_inspection: bool = True,
                      world: bool = True) -> rrb.Blueprint:
    """The layout of logged sessions, with a view only for what they hold: the camera (with the
    ground-truth boxes), the work cell in 3D, the ``depth``, the ``inspection`` view, the
    session, the ``true_state`` as text, the ``truth_series`` (factors, occlusion), and what
    ``perception`` saw (its inspection view if ``perceived_inspection``).

    ``camera_pinhole``, ``inspection_pinhole``: the camera has its intrinsics, so that it shows
    in 3D (an image without them stays out of the 3D view); ``world``: the bodies of the work
    cell or a robot are logged, so that the depth cloud starts hidden in 3D and the 3D view is
    there even without a camera in it.
    """
    camera = f"{RECORD_ROOT}/camera"
    cameras = [name for name, shown in (("camera", camera_pinhole),
                                        ("inspection", inspection and inspection_pinhole))
               if shown]
    top = [rrb.Spatial2DView(origin=camera, contents=["$origin/**", "- $origin/depth"],
                             name="camera + ground-truth boxes" if true_state else "camera")]
    if cameras or world:
        top.append(world_view(RECORD_ROOT, cameras=cameras, world=world))
    below = [rrb.Spatial2DView(origin=camera, contents=["$origin/depth"], name="depth")] \
        if depth else []
    if inspection:
        below.append(rrb.Spatial2DView(origin=f"{RECORD_ROOT}/inspection", name="inspection"))
    left = [rrb.Horizontal(*top)] + ([rrb.Horizontal(*below)] if below else [])
    right = [rrb.TextDocumentView(origin=f"{RECORD_ROOT}/session", name="session")]
    shares = [1]
    if true_state:
        right.append(rrb.TextDocumentView(origin=f"{_TRUTH}/state", name="true state"))
        shares.append(2)
    if truth_series:
        right += [rrb.TimeSeriesView(origin=f"{_TRUTH}/factors", name="true state factors"),
                  rrb.TimeSeriesView(origin=f"{_TRUTH}/occlusion", name="occlusion")]
        shares += [3, 2]
    columns = [rrb.Vertical(*left, row_shares=[2, 1][:len(left)]),
               rrb.Vertical(*right, row_shares=shares)]
    if perception:
        columns.append(rrb.Tabs(*perception_views(inspection=perceived_inspection),
                                name="perception"))
    # the time cursor on ``frame``, which counts on across sessions (``time`` starts again at 0
    # in each one, so that on it every session's series lie on top of each other)
    return rrb.Blueprint(rrb.Horizontal(*columns, column_shares=[3, 2, 2][:len(columns)]),
                         rrb.TimePanel(timeline="frame", state="collapsed"),
                         collapse_panels=True)


class SessionLogger:
    """Logs sessions to one Rerun recording, one after the other.

    Parameters
    ----------
    target : path-like or str
        An ``.rrd`` file, ``"spawn"`` or a gRPC URL (see
        :func:`recordings.rerun.common.open_recording`).
    application_id : str
    perception : bool
        Also log the perception topics of perceived sessions (``perceive/``).
    task : TaskDescription
        The task whose factor series are named when the stream opens (the onion-sorting task by
        default); each session is logged with its own task (``Session.task``), and a session of
        another task gets its series named when it is logged.
    max_depth : float or None
        Depth (m) beyond which the depth image shows nothing (the floor and the far plane
        beyond the work cell; :data:`~recordings.rerun.common.WORK_CELL_DEPTH_M`); None keeps
        every pixel.

    The blueprint (:func:`session_blueprint`) is sent when the logger closes, with a view for
    each thing the sessions hold.

    Examples
    --------
    >>> with SessionLogger("runs/rec/sessions.rrd") as log:  # doctest: +SKIP
    ...     for i, path in enumerate(paths):
    ...         log.log_session(open_session(path), i)
    """

    def __init__(self, target: str | Path, application_id: str = "onionsort", *,
                 perception: bool = True, task: TaskDescription = SORTING_TASK,
                 max_depth: float | None = WORK_CELL_DEPTH_M) -> None:
        # the blueprint follows what the sessions hold: sent once, at close
        self.rec = open_recording(application_id, target)
        self._features = dict.fromkeys((
            "camera_pinhole", "depth", "inspection", "inspection_pinhole", "true_state",
            "truth_series", "perception", "perceived_inspection", "world"), False)
        self.log_perception = perception
        self.task = task
        self.max_depth = max_depth
        log_class_annotations(self.rec)
        self._world = WorldLogger(self.rec, RECORD_ROOT)
        self._named: set[TaskDescription] = set()
        self._name_series(task)
        log_series_names(self.rec, {
            f"{_TRUTH}/occlusion/fraction": "fraction of the view covered",
            f"{_TRUTH}/occlusion/occluded": "occluded step (0/1)"})
        self._perception: PerceptionLogger | None = None
        self._logged = False
        self._frame = 0
        self._step = 0
        self._closed = False

    def _name_series(self, task: TaskDescription) -> None:
        """Log the names of ``task``'s factor series, once per task."""
        if task in self._named:
            return
        self._named.add(task)
        log_series_names(self.rec, {
            f"{_TRUTH}/factors/{name}": f"{name} ({value_labels(values)})"
            for name, values in factor_values(task).items()})

    def __enter__(self) -> SessionLogger:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close()

    def log_session(self, session: Session, index: int) -> None:
        """Log every frame of ``session`` (the ``index``-th of the stream) after those logged
        before it."""
        if self._closed:
            raise ValueError("log_session called on a closed SessionLogger")
        frames = list(session.frames())
        if not frames:
            logger.warning("%s: no complete frame to log", session.path)
            return
        frame0, step0 = self._frame, self._step
        held = self._features
        held["camera_pinhole"] |= self._log_camera(session, frames[0])
        held["inspection_pinhole"] |= self._log_inspection_camera(session, frames)
        tree = None
        if session.robot is not None and any(f.joints for f in frames):
            tree = self._world.robot_model(session.robot["urdf"])
        for n, frame in enumerate(frames):
            self._set_time(frame, frame0, step0)
            if n == 0:
                self.rec.log(f"{RECORD_ROOT}/session", rr.TextDocument(
                    _session_text(session, index), media_type="text/markdown"))
            self._log_frame(session, frame)
            self._log_world(frame, tree)
        if tree is not None:
            self._log_joints(session, frames, tree, frame0, step0)
        if session.has_ground_truth:
            held["truth_series"] |= self._log_truth_series(session, frames, frame0, step0)
        if self.log_perception and session.perception:
            if self._perception is None:
                self._perception = PerceptionLogger(self.rec, task=self.task)
            held["perception"] |= self._perception.log_session(
                session, frame_offset=frame0, step_offset=step0) > 0
            held["perceived_inspection"] |= self._perception.logged_inspection
        held["depth"] |= any(f.depth_raw is not None for f in frames)
        held["inspection"] |= any(f.inspection_png is not None for f in frames)
        held["true_state"] |= any(f.state is not None for f in frames)
        held["world"] |= tree is not None or any(f.scene for f in frames)
        self._logged = True
        self._frame = frame0 + max(f.index for f in frames) + 1
        self._step = step0 + max(max(f.step for f in frames) + 1, len(session.steps))

    def _log_camera(self, session: Session, first: FrameRecord) -> bool:
        """The main camera's pinhole; whether the session had its intrinsics."""
        K = session.metadata.get("camera_K")
        if K is None:
            logger.warning("%s: no camera_K in the session record; the camera is logged "
                           "without intrinsics (and left out of the 3D view)", session.path)
            return False
        h, w = first.color.shape[:2]
        log_pinhole(self.rec, RECORD_ROOT, K, w, h)
        return True

    def _log_inspection_camera(self, session: Session, frames: list[FrameRecord]) -> bool:
        """The inspection view as a pinhole too, so that it shows in 3D where ``/tf`` puts it;
        whether it was logged."""
        K = session.metadata.get("inspection_K")
        first = next((f for f in frames if f.inspection_png is not None), None)
        if K is None or first is None:
            return False
        h, w = first.inspection.shape[:2]
        self.rec.log(f"{RECORD_ROOT}/inspection",
                     rr.Pinhole(image_from_camera=np.asarray(K, float), resolution=[w, h]),
                     static=True)
        return True

    def _log_world(self, frame: FrameRecord, tree: rru.UrdfTree | None) -> None:
        """The frame's 3D side: camera poses and the robot's base (``/tf``), bodies
        (``/scene``)."""
        for frame_id, (parent, t, q) in (frame.transforms or {}).items():
            if parent != WORLD_FRAME:
                continue
            if frame_id in _CAMERA_ENTITIES:
                self._world.log_pose(_CAMERA_ENTITIES[frame_id], t, q)
            elif tree is not None and frame_id == tree.root_link().name:
                self._world.log_robot_base(tree, t, q)
        if frame.scene:
            self._world.log_scene(frame.scene)

    def _log_joints(self, session: Session, frames: list[FrameRecord], tree: rru.UrdfTree,
                    frame0: int, step0: int) -> None:
        """The robot's joints at every frame that has them, one ``send_columns`` per joint."""
        names = list(session.robot.get("joints") or [])
        moving = [f for f in frames if f.joints and all(n in f.joints for n in names)]
        if not names or not moving:
            return
        indexes = [
            rr.TimeColumn("frame", sequence=[frame0 + f.index for f in moving]),
            rr.TimeColumn("step", sequence=[step0 + f.step for f in moving]),
            rr.TimeColumn("time", duration=np.array([f.time_ns for f in moving],
                                                    "timedelta64[ns]")),
        ]
        self._world.send_joints(tree, names, [[f.joints[n] for n in names] for f in moving],
                                indexes)

    def _set_time(self, frame: FrameRecord, frame0: int, step0: int) -> None:
        self.rec.set_time("frame", sequence=frame0 + frame.index)
        self.rec.set_time("step", sequence=step0 + frame.step)
        self.rec.set_time("time", duration=np.timedelta64(int(frame.time_ns), "ns"))

    def _log_frame(self, session: Session, frame: FrameRecord) -> None:
        rec = self.rec
        depth = None
        if frame.depth_raw is not None:
            depth = np.frombuffer(frame.depth_raw, dtype="<u2").reshape(frame.depth_shape)
        log_camera_images(rec, RECORD_ROOT, color_jpeg=frame.color_jpeg, depth=depth,
                          depth_meter=1000.0, max_depth=self.max_depth)
        if frame.inspection_png is not None:
            rec.log(f"{RECORD_ROOT}/inspection",
                    rr.EncodedImage(contents=frame.inspection_png, media_type="image/png"))
        if frame.boxes is not None:
            boxes = frame.boxes
            rec.log(f"{RECORD_ROOT}/camera/color/truth_boxes", rr.Boxes2D(
                array=np.array([[b["x_min"], b["y_min"], b["x_max"], b["y_max"]]
                                for b in boxes], float).reshape(-1, 4),
                array_format=rr.Box2DFormat.XYXY,
                class_ids=[int(b["class_id"]) for b in boxes],
                labels=[f"{b.get('label', '')} #{b.get('onion_id', '?')}" for b in boxes],
            ))
        if frame.state is not None:
            rec.log(f"{_TRUTH}/state", rr.TextDocument(_state_text(frame, session.task),
                                                       media_type="text/markdown"))

    def _log_truth_series(self, session: Session, frames: list[FrameRecord], frame0: int,
                          step0: int) -> bool:
        """The true state's factors and the occlusion as series; whether there were any."""
        first: dict[int, FrameRecord] = {}
        covered: dict[int, float] = {}
        for f in frames:
            first.setdefault(f.step, f)
            if f.state is not None:
                covered[f.step] = max(covered.get(f.step, 0.0),
                                      float(f.state.get("occluded_fraction", 0.0)))
        steps = [s for s in session.steps if s.step in first]
        if not steps:
            return False
        indexes = [
            rr.TimeColumn("step", sequence=[step0 + s.step for s in steps]),
            rr.TimeColumn("frame", sequence=[frame0 + first[s.step].index for s in steps]),
            rr.TimeColumn("time", duration=np.array([first[s.step].time_ns for s in steps],
                                                    "timedelta64[ns]")),
        ]
        task = session.task
        self._name_series(task)
        states = task.decode_array(np.array([s.state for s in steps], np.int64))
        values = {name: [int(v) for v in states[:, k]]
                  for k, name in enumerate(task.factor_names)}
        values["action"] = [s.action for s in steps]
        for name, series in values.items():
            send_series(self.rec, f"{_TRUTH}/factors/{name}", indexes, series)
        send_series(self.rec, f"{_TRUTH}/occlusion/fraction", indexes,
                    [covered.get(s.step, 0.0) for s in steps])
        send_series(self.rec, f"{_TRUTH}/occlusion/occluded", indexes,
                    [float(s.occluded) for s in steps])
        return True

    def close(self) -> None:
        """Send the blueprint of what was logged and flush everything to the file or viewer;
        idempotent."""
        if not self._closed:
            self._closed = True
            try:
                if self._logged:
                    send_layout(self.rec, session_blueprint(**self._features))
            finally:
                close_recording(self.rec)


def _session_text(session: Session, index: int) -> str:
    sides = ["colour"] + (["depth"] if session.has_depth else [])
    sides += ["ground truth"] if session.has_ground_truth else ["no ground truth"]
    if session.perception:
        sides.append("perceived")
    return (f"**session {index}** `{Path(session.path).name}` ({session.status})\n\n"
            f"{session.n_frames} frames, {session.frames_per_step} per step; "
            + ", ".join(sides))


def _state_text(frame: FrameRecord, task: TaskDescription = SORTING_TASK) -> str:
    st = frame.state
    factors = task.decode(int(st["state"]))
    state = ", ".join(f"{f}={task.value_name(f, v)}" for f, v in factors.items())
    action = int(st["action"])
    if not 0 <= action < task.n_actions:
        raise ValueError(f"frame {frame.index}: action must be in [0, {task.n_actions}) of "
                         f"task {task.name!r}; got {action}")
    return (f"**frame** {frame.index} · **step** {frame.step} (phase {frame.phase})\n\n"
            f"**state** {st['state']}: {state}\n\n"
            f"**action** {task.action_names[action]}\n\n"
            f"**occluded step** {bool(st['occluded'])} "
            f"({100 * float(st.get('occluded_fraction', 0.0)):.0f}% of the view covered)")
