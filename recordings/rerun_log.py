"""Log recorded sessions to Rerun: camera with class-annotated boxes, depth, inspection view,
the MDP state as text and as time series, and one blueprint.

Entity paths::

    camera             Pinhole (static) -- camera/color (JPEG), camera/boxes (Boxes2D, XYXY)
    depth              DepthImage (16-bit millimetres, meter=1000)
    inspection         the inspection view (PNG)
    state/text         TextDocument (markdown) of state, action, occlusion
    state/series/*     Scalars: onion, end_effector, prediction, state, action
    occlusion/*        Scalars: fraction of the view covered, occluded step (0/1)

Timelines: ``frame`` and ``step`` (counted across every session logged to the stream) and
``sim_time`` (simulated seconds, restarting with each session), plus ``session`` as a scalar.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from irl.domains.onion_sorting import Location, Prediction, SortAction, decode_state
from recordings.reader import Session
from recordings.schema import CLASS_NAMES

__all__ = ["RerunSessionLogger", "blueprint"]

_CLASS_COLORS = {0: (40, 200, 60), 1: (230, 40, 40)}


def blueprint() -> rrb.Blueprint:
    """The default layout: camera and boxes, depth and inspection, state text and series."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial2DView(origin="camera", name="camera + ground-truth boxes"),
                rrb.Horizontal(rrb.Spatial2DView(origin="depth", name="depth"),
                               rrb.Spatial2DView(origin="inspection", name="inspection")),
                row_shares=[2, 1],
            ),
            rrb.Vertical(
                rrb.TextDocumentView(origin="state/text", name="state"),
                rrb.TimeSeriesView(origin="state/series", name="MDP state factors"),
                rrb.TimeSeriesView(origin="occlusion", name="occlusion"),
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )


class RerunSessionLogger:
    """Logs sessions to one Rerun recording saved to ``target`` (.rrd) or sent to a viewer.

    Parameters
    ----------
    target : path-like or "spawn"
        An ``.rrd`` file to write, or ``"spawn"`` to start (or connect to) a local viewer.
    application_id : str
    """

    def __init__(self, target: str | Path, application_id: str = "onionsort") -> None:
        self.rec = rr.RecordingStream(application_id)
        if str(target) == "spawn":
            self.rec.spawn(default_blueprint=blueprint())
        else:
            path = Path(target)
            if path.suffix != ".rrd":
                raise ValueError(f"target must be an .rrd file or 'spawn'; got {target!r}")
            path.parent.mkdir(parents=True, exist_ok=True)
            self.rec.save(path, default_blueprint=blueprint())
        self.rec.log("/", rr.AnnotationContext([
            (cid, name, _CLASS_COLORS[cid]) for cid, name in CLASS_NAMES.items()]), static=True)
        for name, series in (("state/series/onion", Location),
                             ("state/series/end_effector", Location),
                             ("state/series/prediction", Prediction),
                             ("state/series/action", SortAction)):
            labels = ", ".join(f"{m.value}={m.name.lower()}" for m in series)
            self.rec.log(name, rr.SeriesLines(names=f"{name.rsplit('/', 1)[1]} ({labels})"),
                         static=True)
        self._frame = 0
        self._step = 0

    def log_session(self, session: Session, session_index: int) -> None:
        """Log every frame of ``session``."""
        step_offset = self._step
        first = True
        for frame in session.frames():
            rr_frame = self._frame
            self.rec.set_time("frame", sequence=rr_frame)
            self.rec.set_time("step", sequence=step_offset + frame.step)
            self.rec.set_time("sim_time", duration=frame.time_ns * 1e-9)
            if first:
                h, w = frame.depth_shape
                K = np.array(session.metadata.get("camera_K", np.eye(3).tolist()), float)
                self.rec.log("camera", rr.Pinhole(image_from_camera=K, resolution=[w, h]))
                self.rec.log("session", rr.Scalars(float(session_index)))
                first = False
            self._log_frame(frame)
            self._frame += 1
        self._step = step_offset + len(session.steps)

    def _log_frame(self, frame) -> None:
        rec, st = self.rec, frame.state
        rec.log("camera/color", rr.EncodedImage(contents=frame.color_jpeg, media_type="image/jpeg"))
        h, w = frame.depth_shape
        depth_mm = np.frombuffer(frame.depth_raw, dtype="<u2").reshape(h, w)
        rec.log("depth", rr.DepthImage(depth_mm, meter=1000.0))
        if frame.inspection_png is not None:
            rec.log("inspection",
                    rr.EncodedImage(contents=frame.inspection_png, media_type="image/png"))
        boxes = frame.boxes
        rec.log("camera/boxes", rr.Boxes2D(
            array=np.array([[b["x_min"], b["y_min"], b["x_max"], b["y_max"]] for b in boxes],
                           float).reshape(-1, 4),
            array_format=rr.Box2DFormat.XYXY,
            class_ids=[b["class_id"] for b in boxes],
            labels=[f"{b['label']} #{b['onion_id']}" for b in boxes],
        ))
        s = decode_state(int(st["state"]))
        action = SortAction(int(st["action"]))
        rec.log("state/text", rr.TextDocument(
            f"**frame** {frame.index} · **step** {st['step']} (phase {st.get('phase', 0)})\n\n"
            f"**state** {st['state']}: onion={s.onion.name.lower()}, "
            f"hand={s.end_effector.name.lower()}, prediction={s.prediction.name.lower()}\n\n"
            f"**action** {action.name.lower()}\n\n"
            f"**occluded step** {st['occluded']} "
            f"({100 * float(st.get('occluded_fraction', 0.0)):.0f}% of the view covered)",
            media_type="text/markdown"))
        rec.log("state/series/onion", rr.Scalars(float(s.onion)))
        rec.log("state/series/end_effector", rr.Scalars(float(s.end_effector)))
        rec.log("state/series/prediction", rr.Scalars(float(s.prediction)))
        rec.log("state/series/action", rr.Scalars(float(action)))
        rec.log("occlusion/fraction", rr.Scalars(float(st.get("occluded_fraction", 0.0))))
        rec.log("occlusion/occluded_step", rr.Scalars(float(bool(st["occluded"]))))

    def close(self) -> None:
        """Flush everything to the file or viewer."""
        self.rec.flush()
        self.rec.disconnect()
