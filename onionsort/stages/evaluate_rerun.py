"""Log a sorting evaluation (the Sawyer executing a policy) to Rerun, under one entity root.

:class:`EvaluationLogger` takes each action of the evaluation (its ``on_step``, passed to
:func:`robot.evaluation.evaluate_policy`) and logs the images and the decision at once; the
scalar series are buffered and sent whole by :meth:`EvaluationLogger.close`, one
``send_columns`` call per series. This module does not import ``robot``: what it reads of an
evaluation step is stated by :class:`EvaluationEvent` (``robot.evaluation.EvaluationStep``
satisfies it). Entity paths, under ``root`` (the ``prefix``, ``evaluate`` by default; one
prefix per evaluated policy lets two share a recording)::

    <root>/camera                      Pinhole (static), when the camera's K is given
    <root>/camera/color                Image (JPEG) of the main camera, when rendering
    <root>/camera/depth                DepthImage (metres), when rendering; nothing farther than
                                       the work cell (``max_depth``)
    <root>/inspection                  Pinhole (static), when the inspection camera's K is given
    <root>/inspection/view_K           Image of the robot's K-th view of the onion it inspects
    <root>/inspection/view_K/detections  Boxes2D, when a detector is given: the box the
                                       inspection read, its class the view's own call (its
                                       probability of a blemish against the threshold) and
                                       its label that probability; where the view gave none,
                                       the detector's boxes without a class (grey)
    <root>/inspection/verdict          TextDocument: the robot's fused call on the onion, its
                                       fused probability and each view's, at each inspection
    <root>/inspection/p_blemished      Scalars: the fused probability of each inspection
    <root>/inspection/call             Scalars: the fused call of each inspection (1 blemished,
                                       0 good; none where no view showed the onion)
    <root>/decisions                   TextLog: one line per action (WARN: perception wrong)
    <root>/metrics/{precision,recall}  Scalars: running precision and recall
    <root>/counts/{tp,fp,tn,fn}        Scalars: running counts
    <root>/mdp/{state,action}          Scalars: state index, action index
    <root>/arm/joints                  Scalars: the Sawyer's 7 joint positions (rad)

In 3D (:mod:`recordings.rerun.world`; one 3D view at ``<root>``): given the ``robot`` (its URDF
and base), the Sawyer's meshes under ``<root>/robot`` with its joints animated at every step
from the events' ``q``; given ``camera_pose``, the camera's frustum with its image (the depth
cloud in it hidden at first); given ``inspection_K`` and ``inspection_pose``, the inspection
camera's frustum at its station, with the first view of the onion the Sawyer holds up; an event
that also carries a ``world`` snapshot (:class:`recordings.session.world.World`) adds the work
cell's bodies (``<root>/scene/*``: belt, bin, gate, onions in their true classes' colours).

Timeline: ``step`` (the action number).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from irl.domains.onion_sorting import SORTING_TASK
from irl.domains.task import TaskDescription
from recordings.rerun.common import (
    WORK_CELL_DEPTH_M,
    close_recording,
    log_camera_images,
    log_class_annotations,
    log_pinhole,
    log_series_names,
    open_recording,
    send_layout,
    send_series,
    value_labels,
)
from recordings.rerun.world import WorldLogger, scene_items, world_view
from recordings.session.schema import CLASS_COLORS, CLASS_NAMES
from recordings.session.world import Pose, Robot
from recordings.session.writer import SortingDecision

__all__ = [
    "EVALUATE_ROOT",
    "Detection",
    "EvaluationEvent",
    "EvaluationLogger",
    "evaluation_blueprint",
]

logger = logging.getLogger(__name__)

EVALUATE_ROOT = "evaluate"
_TIMELINE = "step"
_COUNT_COLORS = {"tp": (40, 180, 60), "fp": (230, 120, 30), "tn": (60, 120, 220),
                 "fn": (220, 40, 40)}
_N_JOINTS = 7
#: The factor of the task whose values an event's ``perceived`` holds, and the value that means
#: the onion was seen blemished (a decision the truth contradicts is logged as a warning).
_PERCEIVED_FACTOR, _PERCEIVED_BLEMISHED = "prediction", "bad"
#: The class ids of a call (:data:`~recordings.session.schema.CLASS_NAMES`: their colours too).
_GOOD, _BLEMISHED = 0, 1
#: The colour of a box no inspection call stands behind (the detector's, unread).
_UNREAD = (150, 150, 150)


class EvaluationEvent(SortingDecision, Protocol):
    """What the logger reads of one action of an evaluation
    (``robot.evaluation.EvaluationStep`` satisfies it): a
    :class:`recordings.session.writer.SortingDecision` and the cameras and joints.

    ``state``, ``action`` and ``next_state`` are flat indices of the logger's task; ``onion`` is
    the line-up index of the onion in focus, ``blemished`` its true class, ``perceived`` the
    classifier's answer (a value index of the task's ``prediction`` factor) if this action
    inspected it, ``fate`` (``"bin"`` or ``"line"``) where this action decided it;
    ``tp`` .. ``recall`` are running over the decided onions. ``color`` (H, W, 3) uint8 RGB and
    ``depth`` (H, W) float metres are there when the evaluation renders, ``inspection``
    (h, w, 3) uint8 RGB on inspecting actions; ``q`` (7,) the Sawyer's joint positions. An
    event may also carry ``views`` (every inspection view), ``p_blemished`` (the fused
    probability) and ``view_p_blemished`` (each view's); the logger reads them if present.
    """

    @property
    def color(self) -> np.ndarray | None: ...
    @property
    def depth(self) -> np.ndarray | None: ...
    @property
    def inspection(self) -> np.ndarray | None: ...
    @property
    def q(self) -> np.ndarray: ...


class Detection(Protocol):
    """What the logger reads of a detector's answer on one image: ``boxes`` (n, 4) XYXY
    pixels and their ``scores`` (n,) (its classes are not drawn: a box's class is the
    inspection's call)."""

    @property
    def boxes(self) -> Any: ...
    @property
    def scores(self) -> Any: ...


#: ``detect(images) -> one Detection per image`` (images: list of (h, w, 3) uint8 RGB).
Detect = Callable[[list[np.ndarray]], Sequence[Detection]]


def evaluation_blueprint(prefix: str = EVALUATE_ROOT, views: int = 1, *, color: bool = True,
                         depth: bool = True, p_blemished: bool = True, verdict: bool = True,
                         camera_pinhole: bool = True, inspection_pinhole: bool = True,
                         world: bool = True) -> rrb.Blueprint:
    """The layout, with a view only for what the recording holds: the station's camera
    (``color``, ``depth``), the work cell in 3D, the first ``views`` inspection views with the
    fused call beside them (``verdict``), the decisions, the metrics, ``p_blemished`` and the
    fused call per inspection, the counts and the arm's joints.

    ``camera_pinhole``, ``inspection_pinhole``: the camera or the inspection camera has its
    intrinsics, so that its images show in 3D (an image without them stays out of the 3D
    view); ``world``: the robot or the work cell's bodies are logged, so that the depth cloud
    starts hidden in 3D and the 3D view is there even without a camera in it.
    """
    cameras = [name for name, shown in (("camera", camera_pinhole and (color or depth)),
                                        ("inspection/view_0", inspection_pinhole and views > 0))
               if shown]
    top = []
    if color:
        top.append(rrb.Spatial2DView(origin=f"{prefix}/camera",
                                     contents=["$origin/**", "- $origin/depth"],
                                     name="Sawyer station"))
    if cameras or world:
        top.append(world_view(prefix, name="Sawyer station (3D)", cameras=cameras,
                              world=world))
    below = []
    if views > 0:
        cells: list[Any] = [rrb.Spatial2DView(origin=f"{prefix}/inspection/view_{k}",
                                              name=f"view {k}") for k in range(views)]
        if verdict:
            cells.append(rrb.TextDocumentView(origin=f"{prefix}/inspection/verdict",
                                              name="fused call"))
        below.append(rrb.Grid(*cells, name="inspection"))
    if depth:
        below.append(rrb.Spatial2DView(origin=f"{prefix}/camera", contents=["$origin/depth"],
                                       name="depth"))
    left = [rrb.Horizontal(*rows) for rows in (top, below) if rows]
    series = [rrb.TimeSeriesView(origin=f"{prefix}/metrics", name="precision / recall")]
    if p_blemished:
        series.append(rrb.TimeSeriesView(
            origin=f"{prefix}/inspection",
            contents=["$origin/p_blemished", "$origin/call"] if verdict
            else ["$origin/p_blemished"], name="P(blemished) at inspection"))
    series += [rrb.TimeSeriesView(origin=f"{prefix}/counts", name="TP / FP / TN / FN"),
               rrb.TimeSeriesView(origin=f"{prefix}/mdp", name="state / action"),
               rrb.TimeSeriesView(origin=f"{prefix}/arm", name="Sawyer joints (rad)")]
    right = rrb.Vertical(rrb.TextLogView(origin=f"{prefix}/decisions", name="decisions"),
                         *series)
    if not left:
        return rrb.Blueprint(right, collapse_panels=True)
    return rrb.Blueprint(
        rrb.Horizontal(rrb.Vertical(*left, row_shares=[2, 1][:len(left)]), right,
                       column_shares=[3, 2]),
        collapse_panels=True,
    )


class EvaluationLogger:
    """Logs one evaluation (or several, under different prefixes) to a Rerun recording.

    Parameters
    ----------
    target : path-like or str
        An ``.rrd`` file, ``"spawn"`` or a gRPC URL (see
        :func:`recordings.rerun.common.open_recording`).
    prefix : str
        The entity root of this evaluation.
    detector : callable or object with ``detect``, or None
        ``detect(images) -> detections`` (each with ``boxes`` (n, 4) XYXY and ``scores``), run
        on the inspection views to show the box each view's call is about; an object with a
        ``detect`` method (the perception detector) is taken too.
    camera_K : array-like of shape (3, 3) or None
        The main camera's intrinsics: ``<root>/camera`` becomes a pinhole.
    application_id : str
    task : TaskDescription
        The task of the events' states and actions (names in the decisions and the action
        series); the onion-sorting task by default.
    robot : Robot or None
        The robot (``robot.world.RobotState``: its URDF, base pose and joint names, the names
        of the events' ``q``): shown in 3D from its URDF, its joints animated at every step.
    camera_pose : Pose or None
        The main camera's optical frame in the world (``robot.world.camera_pose``): places its
        frustum and image in 3D.
    views : int
        Inspection views per onion (the layout's grid of them).
    threshold : float in (0, 1)
        The probability of a blemish from which the robot calls an onion blemished (its
        inspection's threshold): each view's box is called blemished where the view's own
        probability reaches it.
    inspection_K : array-like of shape (3, 3) or None
        The inspection camera's intrinsics: ``<root>/inspection`` becomes a pinhole, so that
        the views show in 3D in its frustum (the first view only, the others drawn there
        too would cover it).
    inspection_pose : Pose or None
        The inspection camera's optical frame in the world (the Sawyer's inspection station,
        ``robot.world.camera_pose(ROBOT_INSPECTION_CAMERA)``); an event's ``world`` snapshot
        places it otherwise.
    max_depth : float or None
        Depth (m) beyond which the depth image shows nothing (the floor and the far plane
        beyond the work cell; :data:`~recordings.rerun.common.WORK_CELL_DEPTH_M`); None keeps
        every pixel.

    The blueprint (:func:`evaluation_blueprint`) is sent at :meth:`close`, with a view for what
    the run logged (no slot for an inspection view never used, no image view without images);
    a live viewer shows Rerun's own layout until then.

    Examples
    --------
    >>> with EvaluationLogger("runs/eval/evaluation.rrd", detector=det) as log:  # doctest: +SKIP
    ...     evaluate_policy(..., render=True, on_step=log.on_step)
    """

    def __init__(self, target: str | Path, prefix: str = EVALUATE_ROOT,
                 detector: Detect | Any | None = None, *, camera_K: Any = None,
                 application_id: str = "onionsort_evaluate",
                 task: TaskDescription = SORTING_TASK, robot: Robot | None = None,
                 camera_pose: Pose | None = None, views: int = 1, inspection_K: Any = None,
                 inspection_pose: Pose | None = None,
                 max_depth: float | None = WORK_CELL_DEPTH_M, threshold: float = 0.5) -> None:
        prefix = str(prefix).strip("/")
        if not prefix:
            raise ValueError(f"prefix must name an entity path; got {prefix!r}")
        if not isinstance(threshold, int | float) or not 0.0 < threshold < 1.0:
            raise ValueError(f"threshold must be in (0, 1); got {threshold!r}")
        if detector is not None and not callable(detector):
            detect = getattr(detector, "detect", None)
            if not callable(detect):
                raise ValueError(f"detector must be a callable detect(images) or have a "
                                 f"detect method; got {type(detector).__name__}")
            detector = detect
        if robot is not None and len(robot.joint_names) != _N_JOINTS:
            raise ValueError(f"robot must name the {_N_JOINTS} joints of the events' q; got "
                             f"{list(robot.joint_names)}")
        self.prefix = prefix
        self.task = task
        self.views = max(1, int(views))
        self.threshold = float(threshold)
        self.detect: Detect | None = detector
        self.camera_K = None if camera_K is None else np.asarray(camera_K, float)
        self.inspection_K = None if inspection_K is None else np.asarray(inspection_K, float)
        self.max_depth = max_depth
        self.rec = open_recording(application_id, target)
        log_class_annotations(self.rec)
        self._log_series_names()
        self._world = WorldLogger(self.rec, prefix)
        self._fixed = {name: pose is not None for name, pose in (("camera", camera_pose),
                                                                ("inspection", inspection_pose))}
        for name, pose in (("camera", camera_pose), ("inspection", inspection_pose)):
            if pose is not None:
                self._world.log_pose(f"{prefix}/{name}", pose.position, pose.orientation,
                                     static=True)
        self._robot_tree = None if robot is None else self._world.robot_model(robot.urdf)
        self._joint_names = () if robot is None else tuple(robot.joint_names)
        if self._robot_tree is not None:
            self._world.log_robot_base(self._robot_tree, robot.base.position,
                                       robot.base.orientation, static=True)
        self._rows: dict[str, list] = {}
        self._steps: list[int] = []
        self._closed = False
        # what the recording holds, for its blueprint, sent at close: views never used and
        # images never rendered get no panel
        self._held = {"views": 0, "color": False, "depth": False, "p_blemished": False,
                      "verdict": False,
                      "camera_pinhole": False, "inspection_pinhole": False,
                      "world": self._robot_tree is not None}

    def __enter__(self) -> EvaluationLogger:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close()

    def _log_series_names(self) -> None:
        p = self.prefix
        names: dict[str, str | list[str]] = {
            f"{p}/metrics/precision": "precision", f"{p}/metrics/recall": "recall",
            f"{p}/mdp/state": "state index",
            f"{p}/mdp/action": f"action ({value_labels(self.task.action_names)})",
            f"{p}/arm/joints": [f"right_j{j}" for j in range(_N_JOINTS)],
        }
        names.update({f"{p}/counts/{n}": n.upper() for n in _COUNT_COLORS})
        log_series_names(self.rec, names,
                         colors={f"{p}/counts/{n}": c for n, c in _COUNT_COLORS.items()})
        # one point per inspection, not a line through the steps between
        for entity, name, color, marker in (
                ("p_blemished", "fused P(blemished)", (230, 150, 40), "Circle"),
                ("call", "fused call (1 blemished, 0 good)", (120, 60, 200), "Cross")):
            self.rec.log(f"{p}/inspection/{entity}",
                         rr.SeriesPoints(names=name, colors=[color], markers=marker,
                                         marker_sizes=4.0), static=True)

    def on_step(self, event: EvaluationEvent) -> None:
        """Log one action: images and the decision now, its scalars at :meth:`close`."""
        if self._closed:
            raise ValueError("on_step called on a closed EvaluationLogger")
        p, rec = self.prefix, self.rec
        rec.set_time(_TIMELINE, sequence=int(event.step))
        held = self._held
        for image in (event.color, event.depth):
            if image is not None and self.camera_K is not None and not held["camera_pinhole"]:
                image = np.asarray(image)
                log_pinhole(rec, p, self.camera_K, image.shape[1], image.shape[0])
                held["camera_pinhole"] = True
        if event.color is not None:
            log_camera_images(rec, p, color=np.asarray(event.color), jpeg_quality=90)
            held["color"] = True
        if event.depth is not None:
            log_camera_images(rec, p, depth=np.asarray(event.depth, np.float32),
                              depth_meter=1.0, max_depth=self.max_depth)
            held["depth"] = True
        views = tuple(getattr(event, "views", ()) or ())
        if not views and event.inspection is not None:
            views = (event.inspection,)
        if views:
            self._log_views(event, [np.asarray(v) for v in views])
        text, level = _describe(event, self.task)
        rec.log(f"{p}/decisions", rr.TextLog(text, level=level))
        world = getattr(event, "world", None)
        if world is not None:
            self._world.log_scene(scene_items(world.shapes))
            held["world"] |= bool(world.shapes)
            for name, fixed in self._fixed.items():
                camera = world.cameras.get(name)
                if camera is not None and not fixed:  # else logged static already
                    self._world.log_pose(f"{p}/{name}", camera.position, camera.orientation)
        self._buffer(event)

    def _log_views(self, event: EvaluationEvent, views: list[np.ndarray]) -> None:
        p, rec = self.prefix, self.rec
        found = self.detect(views) if self.detect is not None else [None] * len(views)
        per_view = tuple(getattr(event, "view_p_blemished", ()) or ())
        held = self._held
        if self.inspection_K is not None and not held["inspection_pinhole"]:
            h, w = views[0].shape[:2]
            rec.log(f"{p}/inspection", rr.Pinhole(image_from_camera=self.inspection_K,
                                                  resolution=[w, h]), static=True)
            held["inspection_pinhole"] = True
        held["views"] = max(held["views"], min(len(views), self.views))
        for k, (view, det) in enumerate(zip(views, found, strict=True)):
            rec.log(f"{p}/inspection/view_{k}", rr.Image(view))
            if det is not None:
                p_view = per_view[k] if k < len(per_view) else None
                rec.log(f"{p}/inspection/view_{k}/detections",
                        _boxes(det, p_view, self.threshold))
        for k in range(len(views), self.views):  # an onion settled early: no stale views
            rec.log(f"{p}/inspection/view_{k}", rr.Clear(recursive=True))
        p_bad = getattr(event, "p_blemished", None)
        if p_bad is not None:
            rec.log(f"{p}/inspection/p_blemished", rr.Scalars(float(p_bad)))
            held["p_blemished"] = True
        call = _call(event, self.task)
        if call is not None:
            rec.log(f"{p}/inspection/call", rr.Scalars(float(call)))
        rec.log(f"{p}/inspection/verdict",
                rr.TextDocument(_verdict(event, call, per_view, self.threshold),
                                media_type=rr.MediaType.MARKDOWN))
        held["verdict"] = True

    def _buffer(self, event: EvaluationEvent) -> None:
        p = self.prefix
        q = np.asarray(event.q, float).reshape(-1)
        if q.shape != (_N_JOINTS,):
            raise ValueError(f"event.q must hold {_N_JOINTS} joint positions; got shape "
                             f"{q.shape} at step {event.step}")
        row = {f"{p}/metrics/precision": float(event.precision),
               f"{p}/metrics/recall": float(event.recall),
               f"{p}/mdp/state": float(event.state), f"{p}/mdp/action": float(event.action),
               f"{p}/arm/joints": q}
        row.update({f"{p}/counts/{n}": float(getattr(event, n)) for n in _COUNT_COLORS})
        for entity, value in row.items():
            self._rows.setdefault(entity, []).append(value)
        self._steps.append(int(event.step))

    def close(self) -> None:
        """Send the buffered series and the blueprint of what was logged, and flush everything
        to the file or viewer; idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            if self._steps:
                index = [rr.TimeColumn(_TIMELINE, sequence=self._steps)]
                for entity, values in self._rows.items():
                    send_series(self.rec, entity, index, np.asarray(values, float))
                if self._robot_tree is not None:
                    self._world.send_joints(self._robot_tree, self._joint_names,
                                            np.asarray(self._rows[f"{self.prefix}/arm/joints"]),
                                            index)
                send_layout(self.rec, evaluation_blueprint(self.prefix, **self._held))
        finally:
            close_recording(self.rec)


def _boxes(det: Detection, p_blemished: float | None = None,
           threshold: float = 0.5) -> rr.Boxes2D:
    """The boxes of one view, with one verdict.

    Where the view gave a probability of a blemish, the one box the inspection read (the
    detector's best, :func:`perception.inspection.best_box`) with the view's call as its class
    (blemished where ``p_blemished`` reaches ``threshold``) and the probability as its label;
    the detector's other boxes (the same onion under the other class, mostly) are left out.
    Where it gave none (no box scored enough for the inspection to read it), the detector's
    boxes with their scores, grey and without a class: no call stands behind them. Class,
    colour and label are written every time (the colour of the class spelt out), so that
    nothing of an earlier onion's boxes stays.
    """
    boxes = np.asarray(det.boxes, float).reshape(-1, 4)
    scores = np.asarray(det.scores, float).reshape(-1)
    if p_blemished is not None and len(scores):
        best = int(scores.argmax())
        boxes = boxes[best:best + 1]
        call = _view_call(p_blemished, threshold)
        class_ids, colors = [call], [CLASS_COLORS[call]]
        labels = [f"{CLASS_NAMES[call]}: P(blemished) {p_blemished:.2f}"]
    else:
        class_ids, colors = [], [_UNREAD] * len(boxes)
        labels = [f"not read: onion {s:.2f}" for s in scores]
    return rr.Boxes2D(array=boxes, array_format=rr.Box2DFormat.XYXY, class_ids=class_ids,
                      colors=colors, labels=labels, show_labels=True)


def _view_call(p_blemished: float, threshold: float) -> int:
    """The class id of one view's own call: blemished where its probability reaches
    ``threshold``."""
    return _BLEMISHED if p_blemished >= threshold else _GOOD


def _call(event: EvaluationEvent, task: TaskDescription = SORTING_TASK) -> int | None:
    """The class id of the robot's fused call on the onion ``event`` inspected (None if it
    made none: no view showed the onion)."""
    if event.perceived is None:
        return None
    bad = task.value_index(_PERCEIVED_FACTOR, _PERCEIVED_BLEMISHED)
    return _BLEMISHED if int(event.perceived) == bad else _GOOD


def _verdict(event: EvaluationEvent, call: int | None, per_view: Sequence[float | None],
             threshold: float) -> str:
    """The robot's fused call on the onion ``event`` inspected, as Markdown: the call and its
    probability, each view's own call and probability, the onion's true class."""
    onion = "" if event.onion is None else f"onion {event.onion}: "
    head = (f"**{onion}no call** (no view showed the onion)" if call is None
            else f"**{onion}fused call {CLASS_NAMES[call]}**")
    p_bad = getattr(event, "p_blemished", None)
    if p_bad is not None:
        head += f", P(blemished) {float(p_bad):.2f} (threshold {threshold:.2f})"
    parts = [head]
    rows = []
    for k, p in enumerate(per_view):
        if p is None:
            rows.append(f"- view {k}: no onion found")
        else:
            own = CLASS_NAMES[_view_call(p, threshold)]
            rows.append(f"- view {k}: {own}, P(blemished) {float(p):.2f}")
    if rows:
        parts.append("\n".join(rows))
    if event.blemished is not None:
        parts.append(f"truth: {'blemished' if event.blemished else 'good'}")
    return "\n\n".join(parts)


def _describe(event: EvaluationEvent, task: TaskDescription = SORTING_TASK) -> tuple[str, str]:
    """The decision line of ``event`` (states and actions of ``task``) and its level."""
    s, s_next, a = int(event.state), int(event.next_state), int(event.action)
    if not 0 <= a < task.n_actions:
        raise ValueError(f"event.action must be in [0, {task.n_actions}) of task "
                         f"{task.name!r}; got {a} at step {event.step}")
    text = (f"#{event.step} {task.action_names[a]}: {task.state_name(s)} -> "
            f"{task.state_name(s_next)}")
    level = rr.TextLogLevel.INFO
    if event.onion is not None:
        truth = "blemished" if event.blemished else "good"
        text += f" · onion {event.onion} ({truth})"
    if event.perceived is not None:
        perceived = int(event.perceived)
        text += f" · perceived {task.value_name(_PERCEIVED_FACTOR, perceived)}"
        p_bad = getattr(event, "p_blemished", None)
        if p_bad is not None:
            text += f" (P(blemished) {float(p_bad):.2f})"
        bad = task.value_index(_PERCEIVED_FACTOR, _PERCEIVED_BLEMISHED)
        if (perceived == bad) != bool(event.blemished):
            level = rr.TextLogLevel.WARN
    if event.fate is not None:
        text += f" · fate: {event.fate}"
    if s_next == s:  # flat indices: equal exactly when the factored states are
        text += " · (no effect)"
    return text, level
