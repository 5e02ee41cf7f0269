"""The ``label select`` stage: the frames of recorded sessions most worth a person's labels.

Perception runs on every complete step of the sessions (their sensor side only; ground truth,
where a file has it, is never read). A step's *uncertainty* is the chance, by the models' own
probabilities, that its state guess is wrong (:func:`step_uncertainties`): the occluded call
and, on a step not called occluded, each factor's guess; the prediction's from the
inspection's fused probability, weighed against what the sorter later did with the onion
(:func:`sorter_calls`: the bin or back on the conveyor), or unknown before the session's first
inspection; a step whose guess the sorter's move contradicts counts as at least as likely
wrong as right. Every step more likely wrong than right is taken, the least sure first; the rest
of the budget is spread over the sessions by rounds that take each session's least-sure step
left (the least sure first), until ``frames`` frames; every frame of a taken step is
labelled, so the state classifier gets whole steps. ``sample="random"`` draws the steps
uniformly instead (:func:`_draw`, from ``seed``): frames chosen for being hard would overstate
the error rates that a calibration on held-out sessions measures.

The frames are written as a labelling task pre-annotated with the models' output:

- ``coco``: ``images/`` and ``annotations/instances_default.json`` with the detector's boxes as
  annotations with a ``score`` (each image naming its ``session``, ``step``, ``frame`` and
  ``session_file``), a ``states.csv`` with perception's guesses, and the inspection views of
  those frames in ``inspection/`` in the same layout: what ``label import`` reads back once a
  person has corrected it;
- ``labelstudio``: ``images/``, ``tasks.json`` in Label Studio's import format with
  ``predictions`` and ``labeling_config.xml``, the interface that reads them. A prediction's
  ``score`` is the models' confidence in the step's state guess, one minus its uncertainty (in
  [0, 1]): Label Studio's Data Manager shows the lowest score first, the least sure frame.

``selection.json`` lists the frames taken, each with its uncertainty.

With ``recall``, on sessions that carry ground truth, the choice is scored against the truth
after it is made (:func:`recall`): how many steps have a wrong state guess, how many of the
steps taken do, and each wrong step left out; ``selection.json`` holds that too.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from onionsort.configs.label import SELECT_FORMATS, LabelSelectConfig
from onionsort.stages.base import log_config
from onionsort.stages.label import STATES_FILE, _staging

__all__ = ["SELECT_FORMATS", "SORTER_CONSISTENCY", "LabelSelectConfig", "recall",
           "select_frames", "sorter_calls", "step_uncertainties", "wrong_factors"]

logger = logging.getLogger(__name__)

SORTER_CONSISTENCY = 0.9
"""The chance that the sorter's own later move (the bin, the conveyor) matches what it held
the onion to be (the prediction factor's true value), as :func:`step_uncertainties` weighs
it: set on recorded seeds 900, 902 and 6111 (0.8, 0.9 and 0.95 chose the same wrong steps
there), never on the seeds that docs/lab.md reports."""


def sorter_calls(seen: list) -> list[int]:
    """What the sorter later does with the onion in focus, by perception's own calls, for each
    perceived step of one session (in order): ``+1`` where, from this step on and before a new
    onion is taken up (a claimed onion waiting, an onion just picked), the first step not
    called occluded has the onion in the bin; ``-1`` where it has it on the conveyor; ``0``
    where neither shows or the step's prediction rests on no view. The sorter bins the onions
    it holds blemished and puts back those it holds good, so this is its belief about the
    onion (what the prediction factor stands for), seen in what it did."""
    from irl.domains.onion_sorting import Location

    out = [0] * len(seen)
    for t, step in enumerate(seen):
        if step.p_blemished is None:
            continue
        for u in range(t, len(seen)):
            later = seen[u]
            if later.occluded:
                continue
            if u > t and (int(np.argmax(later.probs["waiting"])) == 1
                          or later.onion == int(Location.HOVER)):
                break
            if later.onion in (int(Location.BIN), int(Location.CONVEYOR)):
                out[t] = 1 if later.onion == int(Location.BIN) else -1
                break
    return out


def step_uncertainties(seen: list, consistency: float = SORTER_CONSISTENCY) -> list[float]:
    """The chance, by the models' own probabilities, that each perceived step of one session
    (:class:`state_abstraction.perceive.PerceivedStep`, in order) has its state guess wrong:
    ``1 - p(occluded call) * prod_f p(guess of f)`` over the state's factors.

    The prediction factor's ``p`` is that of its guess under the inspection's fused
    probability ``p_blemished`` where the inspection has seen the onion in focus, updated by
    what the sorter later did with it (:func:`sorter_calls`) as one more observation that is
    right with chance ``consistency``: the odds ``p_blemished / (1 - p_blemished)`` are
    multiplied by ``consistency / (1 - consistency)`` where it went to the bin and divided by
    it where it went back on the conveyor. (The prediction factor is the sorter's belief; the
    views cannot show a blemish on the side they never see, and the sorter's move shows what
    it believed.) Where the sorter's move contradicts the guess (and ``consistency`` is above
    1/2: the move says something), the step counts as at least as likely wrong as right
    (uncertainty at least 1/2) however sure the views were: the views' probability is the
    models' own, and a confident misreading is what they cannot tell from a right call;
    either the models or the sorter erred there, and a person's label settles which. ``p`` is
    1 where the inspection has not
    seen the onion since a new one was taken up (then ``unknown`` is right), and one over the
    factor's values before the session's first inspection or new onion (as
    :func:`state_abstraction.perceive.track_predictions` starts its memory over: a claimed
    onion waiting, an onion just picked), when the sorter may hold an onion inspected before
    the recording began (nothing shows it)."""
    from irl.domains.onion_sorting import SORTING_TASK, Location, Prediction

    if not 0.5 <= consistency < 1.0:
        raise ValueError(f"consistency must be in [0.5, 1); got {consistency}")
    values = len(SORTING_TASK.factors["prediction"])
    odds = consistency / (1.0 - consistency)
    calls = sorter_calls(seen)
    out, known = [], False
    for step, call in zip(seen, calls, strict=True):
        known |= step.inspected is not None or (not step.occluded and (
            int(np.argmax(step.probs["waiting"])) == 1 or step.onion == int(Location.HOVER)))
        sure = float(step.probs["occluded"][int(step.occluded)])
        if not step.occluded:
            for head in ("onion", "end_effector"):
                sure *= float(np.max(step.probs[head]))
            if step.p_blemished is not None:
                p = min(max(step.p_blemished, 1e-9), 1.0 - 1e-9)
                ratio = p / (1.0 - p) * odds ** call
                p_bad = ratio / (1.0 + ratio)
                sure *= p_bad if step.prediction == int(Prediction.BAD) else 1.0 - p_bad
                if (call and consistency > 0.5
                        and (call > 0) != (step.prediction == int(Prediction.BAD))):
                    sure = min(sure, 0.5)  # the sorter's move contradicts the guess
            elif not known:
                sure /= values
        out.append(1.0 - sure)
    return out


def _choose(scores: list[list[float]], frames_per_step: int, budget: int
            ) -> list[tuple[int, int]]:
    """``(session, step)`` of the steps taken, in the order taken, until ``budget`` frames:
    first every step more likely wrong than right (uncertainty at least 1/2), the least sure
    first; then rounds that take each session's least-sure step left, the least sure first."""
    likely = sorted((-u, k, t) for k, s in enumerate(scores) for t, u in enumerate(s)
                    if u >= 0.5)
    taken = [(k, t) for _, k, t in likely][:budget // frames_per_step]
    done = set(taken)
    order = [[t for t in sorted(range(len(s)), key=lambda t, s=s: (-s[t], t))
              if (k, t) not in done] for k, s in enumerate(scores)]
    next_ = [0] * len(scores)
    while len(taken) * frames_per_step < budget:
        round_ = sorted((-scores[k][order[k][next_[k]]], k) for k in range(len(scores))
                        if next_[k] < len(order[k]))
        if not round_:
            break
        for _, k in round_:
            if len(taken) * frames_per_step >= budget:
                break
            taken.append((k, order[k][next_[k]]))
            next_[k] += 1
    return taken


def wrong_factors(step, guess, task) -> list[str]:
    """What a step's state guess has wrong against the step's truth (its first frame's
    ``state``): ``"occluded"`` where the occluded call is wrong, and on a step truly
    unoccluded and called so, each factor of the task whose value differs."""
    truth = step[0].state
    bad = [] if bool(guess.occluded) == bool(truth["occluded"]) else ["occluded"]
    if not truth["occluded"] and not guess.occluded:
        bad += [f for f in task.factor_names
                if task.value_name(f, getattr(guess, f)) != truth[f]]
    return bad


def recall(steps: list, perceived: list, scores: list[list[float]],
           taken: list[tuple[int, int]], task) -> dict:
    """The choice ``taken`` (``(session, step)`` pairs) scored against the sessions' truth:
    ``steps`` and ``wrong`` (how many steps, and how many with a wrong state guess),
    ``taken`` and ``wrong_taken`` (the same among those taken), ``ratio`` (the wrong share of
    those taken over that of all steps; None where no step is wrong) and ``missed``: each
    wrong step not taken, with its uncertainty and what it has wrong."""
    wrong = {(k, t): wrong_factors(st, guess, task)
             for k, (mine, seen) in enumerate(zip(steps, perceived, strict=True))
             for t, (st, guess) in enumerate(zip(mine, seen, strict=True))}
    chosen = set(taken)
    n_wrong = sum(bool(w) for w in wrong.values())
    hit = sum(bool(wrong[s]) for s in chosen)
    return {"steps": len(wrong), "wrong": n_wrong, "taken": len(chosen), "wrong_taken": hit,
            "ratio": (hit / len(chosen)) / (n_wrong / len(wrong)) if n_wrong else None,
            "missed": [{"session": k, "step": t, "uncertainty": round(scores[k][t], 4),
                        "wrong": w}
                       for (k, t), w in sorted(wrong.items()) if w and (k, t) not in chosen]}


def _draw(scores: list[list[float]], frames_per_step: int, budget: int, seed: int
          ) -> list[tuple[int, int]]:
    """``(session, step)`` of steps drawn uniformly without replacement from every step of
    every session, in the order drawn, until ``budget`` frames: an unbiased sample (what a
    confusion matrix measured on held-out sessions needs), reproducible from ``seed``."""
    every = [(k, t) for k, s in enumerate(scores) for t in range(len(s))]
    order = np.random.default_rng(seed).permutation(len(every))
    return [every[i] for i in order[:-(-budget // frames_per_step)]]  # whole steps


def select_frames(config: LabelSelectConfig, models=None) -> dict:
    """Choose and write the frames (see the module docstring); returns ``frames`` (the list
    of ``selection.json``) and ``steps_seen``, and with ``config.recall`` the choice scored
    against the truth, ``recall`` (:func:`recall`)."""
    from irl.domains.onion_sorting import SORTING_TASK as task
    from onionsort.stages.label import _check_new_folder
    from onionsort.stages.models import PerceptionModels
    from recordings.session.reader import open_session

    log_config("label select", config)
    _check_new_folder(config.out)
    sessions = [open_session(p) for p in config.sessions]
    if config.recall:
        bare = [str(p) for p, s in zip(config.sessions, sessions, strict=True)
                if not s.has_ground_truth]
        if bare:
            raise ValueError(f"{', '.join(bare)} carries no ground truth (a sensor-only "
                             "session): --recall scores the choice against the truth")
    models = PerceptionModels.load(config.models, config.device) if models is None else models
    fps = models.frames_per_step
    for path, s in zip(config.sessions, sessions, strict=True):
        if s.frames_per_step != fps:
            raise ValueError(f"{path}: its steps have {s.frames_per_step} frames; the state "
                             f"classifier reads steps of {fps}")
    steps, perceived, scores = [], [], []
    for session in sessions:
        mine = session.step_frames()
        seen = models.perceive([([f.color for f in step],
                                 [f.depth for f in step] if session.has_depth else None,
                                 [f.inspection if f.inspection_png is not None else None
                                  for f in step]) for step in mine]) if mine else []
        steps.append(mine)
        perceived.append(seen)
        scores.append(step_uncertainties(seen))
    taken = (_choose(scores, fps, config.frames) if config.sample == "uncertain"
             else _draw(scores, fps, config.frames, config.seed))
    if not taken:
        raise ValueError(f"{', '.join(map(str, config.sessions))} hold no complete step")
    chosen = []
    for k, t in sorted(taken):
        frames = steps[k][t][:config.frames] if fps > config.frames else steps[k][t]
        for f in frames:
            chosen.append((k, t, f))
    scored = recall(steps, perceived, scores, taken, task) if config.recall else None
    with _staging(config.out) as tmp:
        selection = _write(config, tmp, chosen, sessions, perceived, scores, models, task,
                           scored)
    out = {"frames": selection, "steps_seen": sum(len(s) for s in steps)}
    if scored is not None:
        out["recall"] = scored
    return out


def _write(config, tmp: Path, chosen, sessions, perceived, scores, models, task,
           scored: dict | None) -> list:
    from onionsort.stages.base import write_json
    from recordings.labels.coco import CocoImage, write_coco
    from recordings.labels.dataset import CLASSES, write_rgb_png
    from recordings.labels.labelstudio import LabelStudioTask, labeling_config, write_tasks
    from recordings.labels.states_csv import StatesRow, write_states

    def name(k: int, frame) -> str:
        return f"{config.sessions[k].stem}_{frame.index:06d}.png"

    colors = [f.color for _, _, f in chosen]
    detections = []
    for i in range(0, len(colors), 32):
        detections.extend(models.detector.detect(colors[i:i + 32]))
    view_of = [(k, t, f) for k, t, f in chosen if f.inspection_png is not None]
    views = models.inspector().detections([f.inspection for _, _, f in view_of]) \
        if view_of else []
    selection, rows, coco, ls_tasks = [], [], [], []
    (tmp / "images").mkdir(parents=True, exist_ok=True)
    for (k, t, f), color, det in zip(chosen, colors, detections, strict=True):
        seen = perceived[k][t]
        factors = {"onion": seen.onion, "end_effector": seen.end_effector,
                   "prediction": seen.prediction}
        where = {"session": k, "step": int(f.step), "frame": int(f.index),
                 "session_file": config.sessions[k].name}
        selection.append({**where, "image": name(k, f), "uncertainty": scores[k][t]})
        write_rgb_png(tmp / "images" / name(k, f), color)
        boxes = np.asarray(det.boxes, float).reshape(-1, 4).tolist()
        height, width = color.shape[:2]
        if config.format == "coco":
            coco.append(CocoImage(name(k, f), width, height, boxes,
                                  np.asarray(det.classes, int).tolist(),
                                  np.asarray(det.scores, float).tolist(), extra=where))
            rows.append(StatesRow(None, name(k, f), k, int(f.step), int(f.index),
                                  bool(seen.occluded), factors, int(seen.action)))
        else:
            choices = {n: task.value_name(n, v) for n, v in factors.items()}
            choices.update(action=task.action_names[seen.action],
                           occluded="yes" if seen.occluded else "no")
            ls_tasks.append(LabelStudioTask(
                f"images/{name(k, f)}", width, height, boxes,
                [CLASSES[c] for c in np.asarray(det.classes, int)],
                np.asarray(det.scores, float).tolist(), choices, 1.0 - scores[k][t], where))
    if config.format == "coco":
        write_coco(tmp / "annotations" / "instances_default.json", coco, CLASSES)
        write_states(tmp / STATES_FILE, rows, task)
        inspection = tmp / "inspection"
        if view_of:
            (inspection / "images").mkdir(parents=True)
        view_images, view_rows = [], []
        for (k, t, f), det in zip(view_of, views, strict=True):
            seen = perceived[k][t]
            write_rgb_png(inspection / "images" / name(k, f), f.inspection)
            h, w = f.inspection.shape[:2]
            view_images.append(CocoImage(
                name(k, f), w, h, np.asarray(det.boxes, float).reshape(-1, 4).tolist(),
                np.asarray(det.classes, int).tolist(), np.asarray(det.scores, float).tolist(),
                extra={"session": k, "step": int(f.step), "frame": int(f.index)}))
            view_rows.append(StatesRow(None, name(k, f), k, int(f.step), int(f.index),
                                       bool(seen.occluded),
                                       {"onion": seen.onion, "end_effector": seen.end_effector,
                                        "prediction": seen.prediction}, int(seen.action)))
        if view_images:
            write_coco(inspection / "annotations" / "instances_default.json", view_images,
                       CLASSES)
            write_states(inspection / STATES_FILE, view_rows, task)
    else:
        described = models.describe()
        write_tasks(tmp / "tasks.json", ls_tasks, "onionsort " + ",".join(
            f"{k}:{str(v)[:12]}" for k, v in described.items() if k != "folder"))
        choices = {n: task.factors[n] for n in ("onion", "end_effector", "prediction")}
        choices.update(action=task.action_names, occluded=("no", "yes"))
        (tmp / "labeling_config.xml").write_text(labeling_config(CLASSES, choices))
    doc = {"measure": "the chance that the step's state guess is wrong, by the models' "
                      "probabilities and what the sorter later did with the onion",
           "frames": selection}
    if scored is not None:
        doc["recall"] = scored
    write_json(tmp / "selection.json", doc)
    return selection
