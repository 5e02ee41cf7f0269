"""Log a learning run (MMAP-BIRL and the other learners) to Rerun, under ``learn/``.

Entity paths::

    learn/objective     Scalars: the objective per iteration (``value``, the log posterior, or
                        ``log_likelihood``, whichever the history records), one send_columns
    learn/theta         TextDocument (static): the learned reward weights (for behaviour
                        cloning, which learns none, a line saying so)
    learn/policy        TextDocument (static): the learned policy, ``state -> action`` (with
                        the action's probability where the model gives one: behaviour cloning)
    learn/confidence    BarChart (static), with a posterior: the confidence in the policy's
                        action per state index
    learn/least_sure   TextDocument (static): per state, its action's confidence, the
                        least sure first

Timeline: ``iteration``.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path

import rerun as rr
import rerun.blueprint as rrb

from irl.learners.optimize import OBJECTIVE_KEYS, objective_curve
from recordings.rerun.common import (
    close_recording,
    log_series_names,
    open_recording,
    send_series,
)

__all__ = ["LEARN_ROOT", "learn_blueprint", "log_learning"]

logger = logging.getLogger(__name__)

LEARN_ROOT = "learn"
#: Keys of a history entry holding the objective, in order of preference.


def learn_blueprint(*, objective: bool = True, confidence: bool = True) -> rrb.Blueprint:
    """The layout: the ``objective`` curve (where the history records one) beside the learned
    reward and policy, and the ``confidence`` in the policy (where a posterior gave one)."""
    model = [rrb.TextDocumentView(origin=f"{LEARN_ROOT}/theta", name="reward weights"),
             rrb.TextDocumentView(origin=f"{LEARN_ROOT}/policy", name="policy")]
    if confidence:
        model += [rrb.BarChartView(origin=f"{LEARN_ROOT}/confidence",
                                   name="confidence per state"),
                  rrb.TextDocumentView(origin=f"{LEARN_ROOT}/least_sure",
                                       name="least sure states")]
    if not objective:
        return rrb.Blueprint(rrb.Vertical(*model), collapse_panels=True)
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.TimeSeriesView(origin=f"{LEARN_ROOT}/objective", name="objective"),
            rrb.Vertical(*model),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )


def log_learning(target: str | Path, model: dict, history: Sequence[dict], *,
                 application_id: str = "onionsort_learn", confidence: dict | None = None
                 ) -> None:
    """Log a learned model and its learning curve to a new recording.

    Parameters
    ----------
    target : path-like or str
        An ``.rrd`` file, ``"spawn"`` or a gRPC URL (see
        :func:`recordings.rerun.common.open_recording`).
    model : dict
        The learned model: ``theta`` (dict of feature name -> weight, or None for a learner
        without a reward) and ``policy`` (list of dicts with ``state`` and ``action``, and
        optionally ``probability``).
    history : sequence of dict
        One entry per iteration, with the objective under ``value`` or ``log_likelihood``.
    application_id : str
    confidence : dict, optional
        ``policy_confidence.json``'s document (``onionsort learn --posterior``): ``states``,
        each with ``state``, ``description``, ``map_action`` and ``confidence``.

    Raises
    ------
    ValueError
        If ``model`` lacks ``theta`` or ``policy``, or ``target`` is not a valid target.
    """
    missing = [k for k in ("theta", "policy") if k not in model]
    if missing:
        raise ValueError(f"model must have 'theta' and 'policy'; missing {missing} in keys "
                         f"{sorted(model)}")
    key, values = objective_curve(history)
    rec = open_recording(application_id, target, learn_blueprint(
        objective=key is not None and len(values) > 0, confidence=confidence is not None))
    try:
        if key is None:  # none at all (a learner with no iterations, bc): nothing to say
            (logger.warning if history else logger.info)(
                "the learning history records no objective (%s); logging the model alone",
                " or ".join(OBJECTIVE_KEYS))
        else:
            log_series_names(rec, {f"{LEARN_ROOT}/objective": f"objective ({key})"})
            send_series(rec, f"{LEARN_ROOT}/objective",
                        [rr.TimeColumn("iteration", sequence=range(len(values)))], values)
        weights = ("no reward: behaviour cloning copies the actions" if model["theta"] is None
                   else "\n".join(f"{name}: {float(w):+.3f}"
                                  for name, w in model["theta"].items()))
        rec.log(f"{LEARN_ROOT}/theta", rr.TextDocument(weights), static=True)
        rec.log(f"{LEARN_ROOT}/policy", rr.TextDocument("\n".join(
            f"{row['state']} -> {row['action']}"
            + (f" ({row['probability']:.2f})" if "probability" in row else "")
            for row in model["policy"])), static=True)
        if confidence is not None:
            rows = confidence["states"]
            sure = [row["confidence"][row["map_action"]] for row in rows]
            rec.log(f"{LEARN_ROOT}/confidence", rr.BarChart(sure), static=True)
            order = sorted(range(len(rows)), key=lambda i: sure[i])
            rec.log(f"{LEARN_ROOT}/least_sure", rr.TextDocument("\n".join(
                f"{sure[i]:.3f}  {rows[i]['map_action']:<18} {rows[i]['state']}: "
                f"{rows[i]['description']}" for i in order)), static=True)
    finally:
        close_recording(rec)
