"""Log what perception made of a session to Rerun, under the entity root ``perceive/``.

Reads the perception topics ``onionsort perceive`` added to a session
(:mod:`recordings.session.perception`): the perceived step (``/perception/state``, kept by the
reader in ``Session.perception``) and the detector's boxes (``/perception/detections`` and
``/perception/inspection``, read here from the file). Entity paths::

    perceive/camera                     Pinhole (static): the main camera's intrinsics
    perceive/camera/color               EncodedImage: the first frame of each step (the one the
                                        estimates are logged at)
    perceive/camera/color/detections    Boxes2D (XYXY, class_ids, scores as labels)
    perceive/inspection                 EncodedImage: the step's inspection view
    perceive/inspection/detections      Boxes2D of the detector on the inspection view
    perceive/observation                TextLog per step: estimates and the pair observation
                                        (WARN where the step was called occluded)
    perceive/factors/*                  Scalars per step: each state factor of the session's
                                        task (onion, end_effector, prediction), and action
    perceive/occlusion/*                Scalars per step: p_occluded, occluded (0/1)

Timelines as in :mod:`recordings.rerun.session`: ``step``, ``frame`` (the step's first frame)
and ``time``; a logger of several sessions passes the offsets of the session in the stream.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from irl.domains.onion_sorting import SORTING_TASK
from irl.domains.task import TaskDescription
from recordings.rerun.common import (
    factor_values,
    log_pinhole,
    log_series_names,
    send_series,
    value_labels,
)
from recordings.session.reader import FrameRecord, Session
from recordings.session.schema import CLASS_NAMES, PerceptionTopic

__all__ = ["PERCEIVE_ROOT", "PerceptionLogger", "perception_views", "read_detections"]

logger = logging.getLogger(__name__)

PERCEIVE_ROOT = "perceive"

#: A stored detection: (x_min, y_min, x_max, y_max, class_id, score).
Detections = dict[int, list[tuple[float, float, float, float, int, float]]]


def perception_views(inspection: bool = True) -> list[rrb.View]:
    """The views of ``perceive/``, for a blueprint: images with the detector's boxes (the
    inspection view's if ``inspection``: the sessions have one), the observations, the
    perceived factors and the occlusion calls."""
    images = [rrb.Spatial2DView(origin=f"{PERCEIVE_ROOT}/camera", name="perceived step")]
    if inspection:
        images.append(rrb.Spatial2DView(origin=f"{PERCEIVE_ROOT}/inspection",
                                        name="inspection detections"))
    return [
        rrb.Vertical(
            *images,
            rrb.TextLogView(origin=f"{PERCEIVE_ROOT}/observation", name="observations"),
            name="perceived images",
        ),
        rrb.Vertical(
            rrb.TimeSeriesView(origin=f"{PERCEIVE_ROOT}/factors", name="perceived factors"),
            rrb.TimeSeriesView(origin=f"{PERCEIVE_ROOT}/occlusion", name="occlusion calls"),
            name="perceived series",
        ),
    ]


def read_detections(path: str | Path) -> tuple[Detections, Detections]:
    """The detector's boxes stored in a perceived session, by frame index.

    Returns
    -------
    camera, inspection : dict of int -> list of (x_min, y_min, x_max, y_max, class_id, score)
        Boxes on the main camera and on the inspection view; empty if the file has none or
        cannot be read (logged as a warning).
    """
    from mcap.reader import make_reader

    out: tuple[Detections, Detections] = ({}, {})
    slot = {PerceptionTopic.DETECTIONS: 0, PerceptionTopic.INSPECTION: 1}
    try:
        with Path(path).open("rb") as fh:
            for _, channel, message in make_reader(fh).iter_messages(topics=list(slot)):
                doc = json.loads(message.data)
                out[slot[channel.topic]][int(doc["frame"])] = [
                    (d["x_min"], d["y_min"], d["x_max"], d["y_max"], int(d["class_id"]),
                     float(d.get("score", 1.0))) for d in doc["detections"]]
    except Exception as exc:  # a damaged file: keep what was read, log the boxes as absent
        logger.warning("%s: could not read the detector's boxes (%s: %s); logging the "
                       "perceived steps without them", path, type(exc).__name__, exc)
    return out


class PerceptionLogger:
    """Logs the perception topics of sessions to an open stream, under ``perceive/``.

    Parameters
    ----------
    rec : rerun.RecordingStream
        An open stream (:func:`recordings.rerun.common.open_recording`) with the class
        annotation context logged.
    images : bool
        Log each step's first frame and inspection view with the detector's boxes.
    task : TaskDescription
        The task whose factor series are named now (the onion-sorting task by default); a
        session of another task gets its series named when it is logged.
    """

    def __init__(self, rec: rr.RecordingStream, *, images: bool = True,
                 task: TaskDescription = SORTING_TASK) -> None:
        self.rec = rec
        self.images = images
        #: Whether an inspection view was logged (``perceive/inspection``).
        self.logged_inspection = False
        self._named: set[TaskDescription] = set()
        self._name_series(task)
        names = {f"{PERCEIVE_ROOT}/occlusion/p_occluded": "P(occluded)",
                 f"{PERCEIVE_ROOT}/occlusion/occluded": "called occluded (0/1)"}
        log_series_names(rec, names)

    def _name_series(self, task: TaskDescription) -> None:
        """Log the names of ``task``'s factor series, once per task."""
        if task in self._named:
            return
        self._named.add(task)
        log_series_names(self.rec, {
            f"{PERCEIVE_ROOT}/factors/{name}": f"perceived {name} ({value_labels(values)})"
            for name, values in factor_values(task).items()})

    def log_session(self, session: Session, *, frame_offset: int = 0,
                    step_offset: int = 0) -> int:
        """Log the perceived steps of ``session``; return how many were logged.

        ``frame_offset`` and ``step_offset`` place the session on the ``frame`` and ``step``
        timelines of a stream holding several sessions.
        """
        if not session.perception:
            logger.warning("%s: not perceived; nothing logged under %s/", session.path,
                           PERCEIVE_ROOT)
            return 0
        frames = {f.index: f for f in session.frames()}
        first: dict[int, FrameRecord] = {}
        for f in frames.values():
            first.setdefault(f.step, f)
        msgs = [session.perception[t] for t in sorted(session.perception)]
        where = [frames.get(int(m.get("frame", -1))) or first.get(int(m["step"]))
                 for m in msgs]
        keep = [(m, f) for m, f in zip(msgs, where, strict=True) if f is not None]
        if len(keep) < len(msgs):
            logger.warning("%s: %d perceived steps have no frame in the file; left out",
                           session.path, len(msgs) - len(keep))
        if not keep:
            return 0
        values = factor_values(session.task)
        self._name_series(session.task)
        if self.images:
            self._log_images(session, keep, frame_offset, step_offset)
        for msg, frame in keep:
            self._set_time(frame, int(msg["step"]), frame_offset, step_offset)
            text, level = _observation_text(msg, values)
            self.rec.log(f"{PERCEIVE_ROOT}/observation", rr.TextLog(text, level=level))
        indexes = [
            rr.TimeColumn("step", sequence=[step_offset + int(m["step"]) for m, _ in keep]),
            rr.TimeColumn("frame", sequence=[frame_offset + f.index for _, f in keep]),
            rr.TimeColumn("time", duration=np.array([f.time_ns for _, f in keep],
                                                    "timedelta64[ns]")),
        ]
        for name in values:
            send_series(self.rec, f"{PERCEIVE_ROOT}/factors/{name}", indexes,
                        [float(m.get(name, np.nan)) for m, _ in keep])
        send_series(self.rec, f"{PERCEIVE_ROOT}/occlusion/p_occluded", indexes,
                    [float(m.get("p_occluded", np.nan)) for m, _ in keep])
        send_series(self.rec, f"{PERCEIVE_ROOT}/occlusion/occluded", indexes,
                    [float(bool(m["occluded"])) for m, _ in keep])
        return len(keep)

    def _set_time(self, frame: FrameRecord, step: int, frame_offset: int,
                  step_offset: int) -> None:
        self.rec.set_time("frame", sequence=frame_offset + frame.index)
        self.rec.set_time("step", sequence=step_offset + step)
        self.rec.set_time("time", duration=np.timedelta64(int(frame.time_ns), "ns"))

    def _log_images(self, session: Session, keep: list[tuple[dict, FrameRecord]],
                    frame_offset: int, step_offset: int) -> None:
        camera, inspection = read_detections(session.path)
        K = session.metadata.get("camera_K")
        if K is not None:
            h, w = keep[0][1].color.shape[:2]
            log_pinhole(self.rec, PERCEIVE_ROOT, K, w, h)
        views = {}
        for f in session.frames():
            if f.inspection_png is not None:
                views.setdefault(f.step, f)
        for msg, frame in keep:
            self._set_time(frame, int(msg["step"]), frame_offset, step_offset)
            self.rec.log(f"{PERCEIVE_ROOT}/camera/color",
                         rr.EncodedImage(contents=frame.color_jpeg, media_type="image/jpeg"))
            self.rec.log(f"{PERCEIVE_ROOT}/camera/color/detections",
                         _boxes(camera.get(frame.index, [])))
            view = views.get(int(msg["step"]))
            if view is not None:
                self.logged_inspection = True
                self.rec.log(f"{PERCEIVE_ROOT}/inspection", rr.EncodedImage(
                    contents=view.inspection_png, media_type="image/png"))
                self.rec.log(f"{PERCEIVE_ROOT}/inspection/detections",
                             _boxes(inspection.get(view.index, [])))
            else:
                self.rec.log(f"{PERCEIVE_ROOT}/inspection", rr.Clear(recursive=True))


def _boxes(dets: list[tuple]) -> rr.Boxes2D:
    array = np.array([d[:4] for d in dets], float).reshape(-1, 4)
    return rr.Boxes2D(array=array, array_format=rr.Box2DFormat.XYXY,
                      class_ids=[int(d[4]) for d in dets],
                      labels=[f"{CLASS_NAMES.get(int(d[4]), d[4])} {d[5]:.2f}" for d in dets])


def _observation_text(msg: dict, values: dict[str, tuple[str, ...]] | None = None
                      ) -> tuple[str, str]:
    """The observation line of a perceived step and its level; ``values`` are the value names
    of each factor and the action (:func:`~recordings.rerun.common.factor_values`, the
    onion-sorting task's by default)."""
    values = factor_values(SORTING_TASK) if values is None else values
    step = int(msg["step"])
    p = msg.get("p_occluded")
    p_text = "" if p is None else f" (P(occluded) {float(p):.2f})"
    if msg["occluded"]:
        return f"#{step} called occluded{p_text}: no observation", rr.TextLogLevel.WARN
    names = []
    for name, labels in values.items():
        if msg.get(name) is not None:
            names.append(f"{name}={_label(labels, int(msg[name]), name)}")
    inspected = msg.get("inspected")
    seen = "" if inspected is None else \
        f" · inspection saw {CLASS_NAMES.get(int(inspected), inspected)}"
    p_bad = msg.get("p_blemished")
    if p_bad is not None:
        seen += f" · P(blemished) {float(p_bad):.2f}"
    return (f"#{step} observation {msg['observation']}: state {msg.get('state', '?')} "
            f"({', '.join(names)}){p_text}{seen}", rr.TextLogLevel.INFO)


def _label(labels: tuple[str, ...], index: int, name: str) -> str:
    """``labels[index]``; ValueError outside ``[0, len(labels))``."""
    if not 0 <= index < len(labels):
        raise ValueError(f"{name} must be in [0, {len(labels)}); got {index}")
    return labels[index]
