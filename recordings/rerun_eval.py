"""Log a sorting evaluation (the Sawyer executing a policy) to Rerun, step by step.

Pass :func:`log_evaluation_step` (bound to a stream with :func:`functools.partial`) as
:func:`robot.evaluation.evaluate_policy`'s ``on_step``. Entity paths, under ``prefix``
(``evaluation`` by default; one prefix per evaluated policy lets two share a recording)::

    {prefix}/camera            Image (JPEG) of the main camera, when the evaluation renders
    {prefix}/depth             DepthImage (metres), when the evaluation renders
    {prefix}/inspection        Image of the inspection view, on steps that inspect
    {prefix}/decisions         TextLog: one line per action (WARN when perception was wrong)
    {prefix}/metrics/*         Scalars: running precision and recall
    {prefix}/counts/*          Scalars: running tp, fp, tn, fn
    {prefix}/mdp/*             Scalars: state index, action index
    {prefix}/arm/joints        Scalars: the Sawyer's 7 joint positions (rad)

Timeline: ``eval_step`` (the action number). Series names and colours are logged statically
with the first step (``event.step == 0``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from irl.domains.onion_sorting import Prediction, SortAction, decode_state

if TYPE_CHECKING:
    from robot.evaluation import EvaluationStep

__all__ = ["TIMELINE", "evaluation_blueprint", "log_evaluation_step"]

TIMELINE = "eval_step"
_COUNT_COLORS = {"tp": (40, 180, 60), "fp": (230, 120, 30), "tn": (60, 120, 220),
                 "fn": (220, 40, 40)}


def evaluation_blueprint(prefix: str = "evaluation") -> rrb.Blueprint:
    """The layout: camera and inspection views, decisions, metrics, counts, arm joints."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial2DView(origin=f"{prefix}/camera", name="Sawyer station"),
                rrb.Horizontal(
                    rrb.Spatial2DView(origin=f"{prefix}/inspection", name="inspection"),
                    rrb.Spatial2DView(origin=f"{prefix}/depth", name="depth"),
                ),
                row_shares=[2, 1],
            ),
            rrb.Vertical(
                rrb.TextLogView(origin=f"{prefix}/decisions", name="decisions"),
                rrb.TimeSeriesView(origin=f"{prefix}/metrics", name="precision / recall"),
                rrb.TimeSeriesView(origin=f"{prefix}/counts", name="TP / FP / TN / FN"),
                rrb.TimeSeriesView(origin=f"{prefix}/arm", name="Sawyer joints (rad)"),
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )


def _log_series_names(rec: rr.RecordingStream, prefix: str) -> None:
    rec.log(f"{prefix}/metrics/precision", rr.SeriesLines(names="precision"), static=True)
    rec.log(f"{prefix}/metrics/recall", rr.SeriesLines(names="recall"), static=True)
    for name, color in _COUNT_COLORS.items():
        rec.log(f"{prefix}/counts/{name}", rr.SeriesLines(names=name.upper(), colors=color),
                static=True)
    actions = ", ".join(f"{a.value}={a.name.lower()}" for a in SortAction)
    rec.log(f"{prefix}/mdp/action", rr.SeriesLines(names=f"action ({actions})"), static=True)
    rec.log(f"{prefix}/mdp/state", rr.SeriesLines(names="state index"), static=True)
    rec.log(f"{prefix}/arm/joints", rr.SeriesLines(names=[f"right_j{j}" for j in range(7)]),
            static=True)


def _describe(event: EvaluationStep) -> tuple[str, str]:
    """The decision line of ``event`` and its level."""
    s, s_next = decode_state(event.state), decode_state(event.next_state)
    action = SortAction(event.action).name.lower()
    text = (f"#{event.step} {action}: ({s.onion.name.lower()}, {s.end_effector.name.lower()}, "
            f"{s.prediction.name.lower()}) -> ({s_next.onion.name.lower()}, "
            f"{s_next.end_effector.name.lower()}, {s_next.prediction.name.lower()})")
    level = rr.TextLogLevel.INFO
    if event.onion is not None:
        truth = "blemished" if event.blemished else "good"
        text += f" · onion {event.onion} ({truth})"
    if event.perceived is not None:
        text += f" · perceived {Prediction(event.perceived).name.lower()}"
        if (event.perceived == Prediction.BAD) != bool(event.blemished):
            level = rr.TextLogLevel.WARN
    if event.fate is not None:
        text += f" · fate: {event.fate}"
    if s_next == s:
        text += " · (no effect)"
    return text, level


def log_evaluation_step(
    rec: rr.RecordingStream, event: EvaluationStep, *, prefix: str = "evaluation"
) -> None:
    """Log one :class:`robot.evaluation.EvaluationStep` to ``rec`` under ``prefix``."""
    if event.step == 0:
        _log_series_names(rec, prefix)
    rec.set_time(TIMELINE, sequence=int(event.step))
    if event.color is not None:
        rec.log(f"{prefix}/camera", rr.Image(np.asarray(event.color)).compress(jpeg_quality=90))
    if event.depth is not None:
        rec.log(f"{prefix}/depth", rr.DepthImage(np.asarray(event.depth, np.float32),
                                                  meter=1.0))
    if event.inspection is not None:
        rec.log(f"{prefix}/inspection", rr.Image(np.asarray(event.inspection)))
    text, level = _describe(event)
    rec.log(f"{prefix}/decisions", rr.TextLog(text, level=level))
    rec.log(f"{prefix}/metrics/precision", rr.Scalars(event.precision))
    rec.log(f"{prefix}/metrics/recall", rr.Scalars(event.recall))
    for name in _COUNT_COLORS:
        rec.log(f"{prefix}/counts/{name}", rr.Scalars(float(getattr(event, name))))
    rec.log(f"{prefix}/mdp/state", rr.Scalars(float(event.state)))
    rec.log(f"{prefix}/mdp/action", rr.Scalars(float(event.action)))
    rec.log(f"{prefix}/arm/joints", rr.Scalars(np.asarray(event.q, float)))
