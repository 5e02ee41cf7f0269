"""Stages ``calibrate`` and ``eval-perception``: measure perception on labelled held-out data.

``calibrate`` runs the detector and the state classifier on a dataset split, measures the
confusion of every factor of the state and of the action on the steps the classifier called
unoccluded (exactly the steps that become observations), and writes the calibration the learners
read (``calibration.json``, with the models' hashes and the depth mode), the observation model it
gives (``observation_model.npz``, ``O[s, a, o]``) and a plot of each confusion matrix.

A calibration holds for one sensor mode: with or without depth (``depth``), with or without the
inspection view (``inspection``; the prediction factor comes from it). A plain video has
neither. It is measured in the mode asked for, with what the mode lacks removed from every step.

Example::

    from onionsort.stages import CalibrateConfig, calibrate
    calibration, metrics = calibrate(CalibrateConfig(data=Path("runs/heldout"), split="all",
                                                     out=Path("runs/calibration")))
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from onionsort.configs.calibrate import CalibrateConfig, PerceptionEvalConfig
from onionsort.stages.base import (
    check_output_folder,
    log_config,
    output_folder,
    refuse_existing,
)
from onionsort.stages.cameras import SessionCameras
from onionsort.stages.models import CALIBRATION_FILE, PerceptionModels
from onionsort.stages.parallel import ParallelOptions, run_pieces

__all__ = [
    "CalibrateConfig",
    "PerceptionEvalConfig",
    "SessionCameras",
    "calibrate",
    "dataset_identity",
    "describe_session_swaps",
    "detector_map",
    "eval_perception",
    "measure_perception",
    "perception_figures",
    "shift_summary",
    "worse_when_higher",
]

logger = logging.getLogger(__name__)


def measure_perception(models: PerceptionModels | tuple, root: Path | str,
                       split: str = "test", *, depth: bool = True, inspection: bool = True,
                       options: ParallelOptions | None = None, image_map=None):
    """Perceive every step of a dataset split and compare with the truth.

    ``image_map`` changes every colour image as it is read
    (:data:`recordings.labels.dataset.ImageMap`, e.g. :class:`SessionCameras`; picklable when the
    sessions are perceived on workers).

    ``models`` are the loaded models, which perceive the split's sessions here, one after
    another; or ``(folder, device)``, and the sessions are perceived on ``options``'s workers
    (each a piece, each worker loading the models once), with the same result.

    Returns
    -------
    calibration : state_abstraction.calibration.Calibration
        Confusion of each factor on the steps the classifier called unoccluded, with the
        models and the sensor mode (depth, inspection) recorded.
    metrics : dict
        ``accuracy`` per factor on truly unoccluded steps, ``occlusion_recall``,
        ``occlusion_precision``, ``n_steps``, ``n_occluded``, ``depth``, ``inspection``.
    """
    from recordings.labels.dataset import read_steps, split_sessions
    from state_abstraction.calibration import FACTORS, calibrate

    if isinstance(models, tuple):  # the workers load the models: this process reads no torch
        folder, device = models
        frames = PerceptionModels.frames_per_step_for_workers(folder, device)
        described = PerceptionModels.describe_folder(folder)
        sessions = split_sessions(root, split)
        measured = [None] * len(sessions)
        for i, result in run_pieces(
                _measure_piece, [(models, root, name, session, frames, depth, inspection,
                                  image_map) for name, session in sessions],
                options or ParallelOptions(), names=[f"{root} ({name}) session {session}"
                                                     for name, session in sessions],
                desc="calibrate", unit="session"):
            measured[i] = result
    else:
        described = models.describe()
        measured = [_measure_session(models, steps, depth, inspection)
                    for steps in read_steps(root, split, models.frames_per_step,
                                            image_map=image_map)]
    true = {k: [v for m in measured for v in m["true"][k]] for k in FACTORS}
    pred = {k: [v for m in measured for v in m["pred"][k]] for k in FACTORS}
    truly_occluded, called_occluded, inspected_before = (
        [v for m in measured for v in m[key]]
        for key in ("occluded", "called_occluded", "inspected_before"))
    if not true["onion"]:
        raise ValueError(f"split {split!r} of {root} holds no complete step")
    occ, called = np.array(truly_occluded), np.array(called_occluded)
    observed = ~called
    calibration = calibrate({k: np.array(v)[observed] for k, v in true.items()},
                            {k: np.array(v)[observed] for k, v in pred.items()})
    visible = ~occ
    metrics = {
        "accuracy": {k: float(np.mean(np.array(true[k])[visible] == np.array(pred[k])[visible]))
                     for k in FACTORS},
        # the prediction factor from the session's first inspection on: before it, the sorter
        # may hold an onion inspected before the recording began, which no sensor shows
        "prediction_after_first_inspection": _mean_or_none(
            np.array(true["prediction"]) == np.array(pred["prediction"]),
            visible & np.array(inspected_before)),
        "occlusion_recall": float(called[occ].mean()) if occ.any() else 1.0,
        "occlusion_precision": float(occ[called].mean()) if called.any() else 1.0,
        "n_steps": len(occ),
        "n_occluded": int(occ.sum()),
        "depth": depth,
        "inspection": inspection,
    }
    swaps = session_swaps(measured)
    metrics["session_swaps"] = {k: swaps[k] for k in ("sessions", "swapped", "reads",
                                                      "swapped_reads")}
    return (replace(calibration, models=described, depth=depth, inspection=inspection,
                    session_swaps={k: swaps[k] for k in ("sessions", "swapped",
                                                         "prediction_counts")}), metrics)


#: Fewest reads of the onion's class that let a session count as read swapped or not.
MIN_CLASS_READS = 3


def session_swaps(measured: list[dict]) -> dict:
    """How often perception read the onion's class backwards for a whole session.

    Per session (each of ``measured`` as :func:`_measure_session` gives it): its reads of a
    good or blemished onion as good or blemished, on the steps not called occluded, and how
    many of them were the other class. A session with at least :data:`MIN_CLASS_READS` such
    reads counts as *swapped* when more than half of them were. Returns ``sessions`` (those
    counted), ``swapped``, per session ``reads`` and ``swapped_reads``, and
    ``prediction_counts``: the prediction factor's confusion on the steps not called occluded
    with the swapped sessions' class reads swapped back, i.e. the confusion within a session
    given how it was read (what a learner that models the swaps needs).
    """
    from irl.domains.onion_sorting import SORTING_TASK
    from state_abstraction.calibration import confusion_counts

    good, bad = (SORTING_TASK.value_index("prediction", v) for v in ("good", "bad"))
    back = np.arange(len(SORTING_TASK.factors["prediction"]))
    back[[good, bad]] = [bad, good]
    reads, wrong, swapped, true_all, pred_all = [], [], [], [], []
    for m in measured:
        seen = ~np.array(m["called_occluded"], dtype=bool)
        true = np.array(m["true"]["prediction"], dtype=np.int64)[seen]
        pred = np.array(m["pred"]["prediction"], dtype=np.int64)[seen]
        keep = np.isin(true, (good, bad)) & np.isin(pred, (good, bad))
        reads.append(int(keep.sum()))
        wrong.append(int((true[keep] != pred[keep]).sum()))
        swapped.append(reads[-1] >= MIN_CLASS_READS and 2 * wrong[-1] > reads[-1])
        true_all.append(true)
        pred_all.append(back[pred] if swapped[-1] else pred)
    counts = confusion_counts(np.concatenate(true_all) if true_all else np.zeros(0, int),
                              np.concatenate(pred_all) if pred_all else np.zeros(0, int),
                              back.size, "prediction")
    return {"sessions": sum(n >= MIN_CLASS_READS for n in reads), "swapped": sum(swapped),
            "reads": reads, "swapped_reads": wrong, "prediction_counts": counts.tolist()}


def describe_session_swaps(swaps: dict) -> str:
    """One line: how many sessions perception read backwards (:func:`session_swaps`)."""
    return (f"{swaps['swapped']} of {swaps['sessions']} sessions read backwards (of those "
            f"with at least {MIN_CLASS_READS} reads of the onion's class: more than half of "
            "them the other class)")


def _measure_session(models: PerceptionModels, steps, depth: bool, inspection: bool) -> dict:
    """Perceive one dataset session's steps: per step, each factor's truth (``true``) and
    perceived value (``pred``), whether it was occluded and called so, and whether the
    session had shown an inspection by then."""
    from state_abstraction.calibration import FACTORS

    perceived = models.perceive([(s.colors, s.depths if depth else None,
                                  s.views if inspection else None) for s in steps]
                                ) if steps else []
    out = {"true": {k: [] for k in FACTORS}, "pred": {k: [] for k in FACTORS},
           "occluded": [], "called_occluded": [], "inspected_before": []}
    seen_inspection = False
    for step, seen in zip(steps, perceived, strict=True):
        seen_inspection |= seen.inspected is not None
        out["inspected_before"].append(seen_inspection)
        out["occluded"].append(bool(step.record["occluded"]))
        out["called_occluded"].append(seen.occluded)
        for k in FACTORS:
            out["true"][k].append(int(step.record[k]))
            out["pred"][k].append(int(getattr(seen, k)))
    return out


def _measure_piece(piece: tuple) -> dict:
    """:func:`_measure_session` of one session of a dataset split, read alone: ``piece`` is
    ``((folder, device), root, split name, session, frames per step, depth, inspection,
    image_map)``."""
    from recordings.labels.dataset import read_steps

    (folder, device), root, name, session, frames, depth, inspection, image_map = piece
    models = PerceptionModels.load_cached(folder, device)
    return _measure_session(models, [step for steps in read_steps(root, name, frames,
                                                                  session=session,
                                                                  image_map=image_map)
                                     for step in steps], depth, inspection)


def _mean_or_none(values: np.ndarray, where: np.ndarray) -> float | None:
    return float(values[where].mean()) if where.any() else None


def detector_map(models: PerceptionModels, root: Path | str, split: str = "test",
                 batch_size: int = 32, *, image_map=None,
                 views: Sequence[str] | None = None) -> dict[str, dict[str, float]]:
    """mAP of the detector on a dataset split: ``{"all" | "camera" | "inspection": {...}}``
    (the Sawyer's views by its own detector where the models have one; each colour image
    changed by ``image_map`` first, if given; ``views``: only these of the dataset's views,
    ``"all"`` then being theirs). Besides COCO's figures,
    ``map50_any_class`` is mAP@0.5 with every box one class: whether the detector finds the
    onions, apart from the good/blemished call it puts on them, which nothing downstream reads
    (the inspection classifier makes the class call)."""

    from perception.metrics import mean_average_precision
    from perception.train_detector import EVAL_SCORE_THRESHOLD
    from recordings.labels.dataset import read_metadata, read_split, split_names

    views = list(read_metadata(root).get("views", ["camera"]) if views is None else views)
    gts: dict[str, list] = {}
    dts: dict[str, list] = {}
    frames: dict[str, list] = {}
    for view in views:
        frames[view] = [f for name in split_names(split)
                        for f in read_split(root, name, view=view, image_map=image_map)]
        gts[view] = [(np.asarray(f.record["boxes"], float).reshape(-1, 4),
                      np.asarray(f.record["classes"], int)) for f in frames[view]]
        dts[view] = [None] * len(frames[view])
        for camera in ("sorter", "robot"):  # the Sawyer's views by its own detector, if any
            mine = [i for i, f in enumerate(frames[view])
                    if (f.record.get("source") == "robot") == (camera == "robot")]
            for start in range(0, len(mine), batch_size):
                rows = mine[start:start + batch_size]
                found = models.detector_for(camera).detect(
                    [frames[view][i].color for i in rows], score_threshold=EVAL_SCORE_THRESHOLD)
                for i, det in zip(rows, found, strict=True):
                    dts[view][i] = det

    def figures(g: list, d: list) -> dict[str, float]:
        found = [(x.boxes, x.scores, x.classes) for x in d]
        return {**mean_average_precision(g, found),
                "map50_any_class": mean_average_precision(g, found, any_class=True)["map50"]}

    out = {v: figures(gts[v], dts[v]) for v in views}
    out["all"] = figures([g for v in views for g in gts[v]], [d for v in views for d in dts[v]])
    return out


def calibrate(config: CalibrateConfig, models: PerceptionModels | None = None):
    """Measure perception on ``config.data`` and write the calibration into ``config.out``.

    Returns ``(calibration, metrics)`` (see :func:`measure_perception`).
    """
    from onionsort.plots import confusion_figure

    log_config("calibrate", config)
    refuse_existing(config.out / CALIBRATION_FILE, config.overwrite)
    with output_folder(config.out) as out:
        if models is None and (config.executor == "ray" or config.n_workers > 1):
            models = (config.models, config.device)  # the workers load them
        elif models is None:
            models = PerceptionModels.load(config.models, config.device)
        calibration, metrics = measure_perception(models, config.data, config.split,
                                                  depth=config.depth,
                                                  inspection=config.inspection,
                                                  options=config.parallel_options())
        calibration = calibration.with_smoothing(config.smoothing)
        calibration.save(out / CALIBRATION_FILE, extra={
            "data": dataset_identity(config.data), "split": config.split,
            "models": calibration.models,
            "depth": config.depth, "inspection": config.inspection, "metrics": metrics})
        tmp = out / "observation_model.partial.npz"
        np.savez_compressed(tmp, probs=calibration.observation_model().probs)
        tmp.replace(out / "observation_model.npz")
        confusion_figure(calibration, out / "confusion.png")
    return calibration, metrics


def dataset_identity(root: Path | str) -> dict:
    """A dataset as a calibration records it: its folder's name, seed, size and difficulty (a
    path would name a folder on one machine only)."""
    from recordings.labels.dataset import read_metadata

    meta = read_metadata(root)
    difficulty = meta.get("config", {}).get("difficulty", "clean")
    levels = ([d["name"] for d in difficulty] if isinstance(difficulty, list)
              else difficulty["name"] if isinstance(difficulty, dict) else difficulty)
    return {"name": Path(root).resolve().name, "seed": meta.get("seed"),
            "frames": meta.get("frames"), "difficulty": levels}


def eval_perception(config: PerceptionEvalConfig, models: PerceptionModels | None = None
                    ) -> dict:
    """mAP of the detector, the state classifier's accuracy and the inspection on a dataset
    split; with ``config.camera_shift``, the same again through other cameras, once per seed
    (:class:`SessionCameras`), under ``"camera_shift"``: ``seeds``, ``one_camera``,
    ``sessions`` (those with a class read, which may be read backwards), ``shifted`` (one
    result per seed, the same keys as the unchanged one, measured on the changed images) and
    ``figures`` (:func:`shift_summary`). Each seed's figures are those
    that seed gives alone: a seed's cameras do not depend on the other seeds."""
    log_config("eval-perception", config)
    if config.plots is not None:
        check_output_folder(config.plots, "--plots")
    models = PerceptionModels.load(config.models, config.device) if models is None else models
    out = _eval_figures(models, config, None)
    if config.inspection and config.plots is not None:
        from onionsort.plots import precision_recall_figure

        out["plots"] = [str(p) for p in precision_recall_figure(
            out["inspection_classifier"], config.plots)]
    if config.camera_shift is not None:
        shifted = [_eval_figures(models, config, SessionCameras(seed, config.one_camera))
                   for seed in config.camera_shift]
        out["camera_shift"] = {"seeds": list(config.camera_shift),
                               "one_camera": config.one_camera,
                               "sessions": out["session_swaps"]["sessions"], "shifted": shifted,
                               "figures": shift_summary(out, shifted)}
    return out


def perception_figures(r: dict) -> dict[str, float | None]:
    """The figures of one :func:`eval_perception` result by name, in the order ``onionsort
    eval-perception`` prints them (beside those through other cameras)."""
    out: dict[str, float | None] = {}
    for view, m in r["map_by_view"].items():
        out[f"detector mAP@0.5, {view}"] = m["map50"]
        if "map50_any_class" in m:
            out[f"detector mAP@0.5 any class, {view}"] = m["map50_any_class"]
    out.update({f"state: {k}": v for k, v in r["accuracy"].items()})
    out["state: prediction after the first inspection"] = r["prediction_after_first_inspection"]
    out["occluded: recall"] = r["occlusion_recall"]
    out["occluded: precision"] = r["occlusion_precision"]
    for level, sources in r.get("inspection_classifier", {}).get("levels", {}).items():
        for source, m in sources.items():
            who = f"inspection {level} {source}"
            out[f"{who}: onion found"] = m["found"]
            out[f"{who}: rot call per view"] = m["rot_accuracy"]
            out[f"{who}: class call per view"] = m["view_accuracy"]
            for rule, f in m["fused"].items():
                out[f"{who}: fused by {rule}, accuracy"] = f["accuracy"]
                out[f"{who}: fused by {rule}, precision"] = f["precision"]
                out[f"{who}: fused by {rule}, recall"] = f["recall"]
                out[f"{who}: fused by {rule}, ECE"] = f["ece"]
                out[f"{who}: fused by {rule}, ECE by chance"] = f.get("ece_by_chance")
                out[f"{who}: fused by {rule}, ECE by chance, 90th percentile"] = f.get(
                    "ece_by_chance_90")
    return out


def worse_when_higher(name: str) -> bool:
    """Whether a figure of :func:`perception_figures` (or the sessions read backwards) is
    worse when higher: a calibration error, a count of sessions read backwards."""
    return "ECE" in name or name == "sessions read backwards"


def shift_summary(unchanged: dict, shifted: list[dict]) -> dict[str, dict]:
    """Each figure of :func:`perception_figures`, and ``"sessions read backwards"``, through
    the cameras of several seeds: ``unchanged``, ``changed`` (one value per seed, in the
    seeds' order), their ``mean``, the ``worst`` of them, and the drops, how much worse than
    unchanged: ``mean_drop`` and ``worst_drop`` (a fall, or for an ECE and the sessions read
    backwards a rise; negative where it got better). A figure that is None unchanged or
    through a camera has None for what needs it."""
    before = perception_figures(unchanged)
    before["sessions read backwards"] = unchanged["session_swaps"]["swapped"]
    afters = []
    for r in shifted:
        figures = perception_figures(r)
        figures["sessions read backwards"] = r["session_swaps"]["swapped"]
        afters.append(figures)
    out = {}
    for name, value in before.items():
        changed = [a.get(name) for a in afters]
        sign = -1.0 if worse_when_higher(name) else 1.0
        known = [v for v in changed if v is not None]
        full = len(known) == len(changed) and bool(known)
        mean = float(np.mean(known)) if full else None
        worst = (max(known) if sign < 0 else min(known)) if full else None
        out[name] = {
            "unchanged": value, "changed": changed, "mean": mean, "worst": worst,
            "mean_drop": None if value is None or mean is None else sign * (value - mean) + 0.0,
            "worst_drop": (None if value is None or worst is None
                           else sign * (value - worst) + 0.0)}  # + 0.0: no -0.0
    return out


def _eval_figures(models: PerceptionModels, config: PerceptionEvalConfig, image_map) -> dict:
    """:func:`eval_perception`'s figures, each colour image changed by ``image_map``."""
    from onionsort.stages.inspection import measure_inspection

    _, metrics = measure_perception(models, config.data, config.split, depth=config.depth,
                                    inspection=config.inspection, image_map=image_map)
    maps = detector_map(models, config.data, config.split, image_map=image_map)
    out = {"data": dataset_identity(config.data),
           "map50": maps["all"]["map50"], "map50_95": maps["all"]["map50_95"],
           "accuracy": metrics["accuracy"], "occlusion_recall": metrics["occlusion_recall"],
           "occlusion_precision": metrics["occlusion_precision"],
           "prediction_after_first_inspection": metrics["prediction_after_first_inspection"],
           "session_swaps": metrics["session_swaps"],
           "map_by_view": maps, "n_steps": metrics["n_steps"], "split": config.split,
           "depth": config.depth, "inspection": config.inspection}
    if config.inspection:
        out["inspection_classifier"] = measure_inspection(models, config.data, config.split,
                                                          views=config.views,
                                                          image_map=image_map)
    return out
