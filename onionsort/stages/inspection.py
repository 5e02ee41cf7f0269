"""The inspection classifier from a dataset: its crops, its training, its measurement.

The library (:mod:`perception.inspection`, :mod:`perception.train_inspection`) trains on crops
held in memory and reads no dataset; this module reads a dataset's inspection views with
:mod:`recordings.labels.dataset` (the sorter's, ``source: human``, and the Sawyer's,
``source: robot``, at every difficulty level the dataset holds), cuts the crops, weighs them,
and groups the views of each onion so that their fused call can be measured.

Weights: each (difficulty level, source, label) cell of the training and validation views
weighs the same in all, times the level's weight (``level_weights``; 1 each by default): the
``clean`` call learns as much as the hardest level's, and the sorter's few views as much as the
robot's many.

Example::

    from onionsort.stages.inspection import InspectionTrainStageConfig, train_inspection_stage
    metrics = train_inspection_stage(InspectionTrainStageConfig(data=Path("runs/data"),
                                                                out=Path("runs/models")))
"""

from __future__ import annotations

import logging
from collections import defaultdict
from pathlib import Path

import numpy as np

from onionsort.configs.inspection import (
    CALIBRATION_FORMS,
    INSPECTION_CAMERAS,
    FusionCalibrationConfig,
    InspectionTrainStageConfig,
)
from onionsort.stages.base import check_output_folder, log_config, write_json
from onionsort.stages.inspection_views import MIN_CROP_PIXELS, InspectionViews, inspection_views

__all__ = [
    "CALIBRATION_FORMS",
    "INSPECTION_CAMERAS",
    "MIN_CROP_PIXELS",
    "FusionCalibrationConfig",
    "InspectionTrainStageConfig",
    "InspectionViews",
    "fit_fused_calibration",
    "fit_robot_fusion_stage",
    "fit_side_map",
    "inspection_views",
    "measure_inspection",
    "train_inspection_stage",
]

logger = logging.getLogger(__name__)


def _load_detectors(folder: Path | None, device) -> dict:
    """The detectors of ``folder`` (default: shipped) as :func:`inspection_views` takes them:
    ``detector`` and, where the folder has one, the Sawyer's own ``robot_detector``."""
    from onionsort.stages.models import DEFAULT_MODELS, DETECTOR_FILE, ROBOT_DETECTOR_FILE
    from perception import Detector

    folder = DEFAULT_MODELS if folder is None else Path(folder)
    if not (folder / DETECTOR_FILE).is_file():
        raise FileNotFoundError(f"{folder} has no {DETECTOR_FILE}; train it with "
                                f"`onionsort train detector --data DATASET --out {folder}`")
    robot = folder / ROBOT_DETECTOR_FILE
    return {"detector": Detector.load(folder / DETECTOR_FILE, device=device),
            "robot_detector": Detector.load(robot, device=device) if robot.is_file() else None}


def train_inspection_stage(config: InspectionTrainStageConfig) -> dict:
    """Train the inspection classifier on ``config.data``'s train splits; choose its fusion
    rule on the validation splits' onions; write ``inspection_classifier.pt`` and
    ``inspection_metrics.json`` into ``config.out`` (with ``camera="robot"``,
    ``robot_inspection_classifier.pt`` and ``robot_inspection_metrics.json``, so that both
    can be trained into one models folder; with ``camera="sorter"`` the shared files, learnt
    from the sorter's views alone).

    Returns
    -------
    dict
        The metrics written: training history, calibration, and per rule the validation
        onions' fused log-loss and accuracy (``rules``), the ``rule`` chosen (``config.fusion``,
        else the one of lower log-loss), and the classifier's ``file`` name.
    """
    import torch

    from onionsort.stages.base import resolve_device
    from onionsort.stages.models import INSPECTION_FILE
    from onionsort.stages.parallel import torch_threads
    from onionsort.stages.train import epoch_bar
    from perception.fusion import FUSION_RULES
    from perception.train_inspection import CropSet, InspectionTrainConfig, train_inspection

    log_config("train inspection", config)
    device = resolve_device(config.device)
    check_output_folder(config.out)
    torch.set_num_threads(torch_threads())
    detectors = _load_detectors(config.detector, device)
    if config.init is not None and not Path(config.init).is_file():
        raise FileNotFoundError(f"{config.init}: no such inspection classifier to start from")
    train_cameras, val_cameras = _cameras(config.through_cameras)
    framing = detectors if config.crops == "detected" else {}
    parts = [(inspection_views(d, "train", **framing, context=True,
                               allow_empty=len(config.data) > 1, image_map=camera), weight)
             for camera in train_cameras for d, weight in zip(config.data, config.data_weights,
                                                              strict=True)]
    train = InspectionViews.concat([views for views, _ in parts])
    counts = np.repeat([w for _, w in parts], [len(v) for v, _ in parts]).astype(float)
    if framing:  # the views its detector finds no onion in teach nothing
        found = train.found.astype(bool)
        logger.info("the detector finds the onion in %d of %d training views",
                    int(found.sum()), len(found))
        train, counts = train.subset(found), counts[found]
    val = InspectionViews.concat([inspection_views(d, "val", **detectors,
                                                   allow_empty=len(config.data) > 1,
                                                   image_map=camera)
                                  for camera in val_cameras for d in config.data])
    val = val.subset(val.found.astype(bool))  # an empty set's columns are float
    if config.camera != "both":  # one camera's views alone
        source = "robot" if config.camera == "robot" else "human"
        counts = counts[train.source == source]
        train, val = (views.subset(views.source == source) for views in (train, val))
        if not len(train) or not len(val):
            how = ("render them with `onionsort dataset --robot-onions N`"
                   if source == "robot" else "render sessions with `onionsort dataset`")
            raise ValueError(f"{', '.join(map(str, config.data))} hold no {config.camera} "
                             f"views in their {'train' if not len(train) else 'val'} splits; "
                             + how)
    logger.info("inspection views: %d train (%d show rot), %d val", len(train),
                int((train.labels == 1).sum()), len(val))
    if not len(train) or not len(val):
        raise ValueError(f"{', '.join(map(str, config.data))} hold no inspection view of an "
                         f"onion in their {'train' if not len(train) else 'val'} splits")
    weights = train.weights(config.level_weights)
    if (counts != 1).any():  # each dataset's views counted its weight's times
        weights = weights * counts * len(weights) / (weights * counts).sum()
    train_set = CropSet(train.crops, train.labels, train.classes, weights)
    val_set = CropSet(val.crops, val.labels, val.classes, val.weights(config.level_weights))
    with epoch_bar("inspection classifier", config.epochs) as on_epoch:
        classifier, metrics = train_inspection(
            train_set, val_set, InspectionTrainConfig(epochs=config.epochs,
                                                      batch_size=config.batch_size,
                                                      seed=config.seed, lr=config.lr,
                                                      photometric=config.augment),
            device=device, on_epoch=on_epoch, init=config.init)
    if config.visibility is not None:
        classifier.visibility = float(config.visibility)
        metrics.update(visibility_measured=metrics["visibility"], visibility=config.visibility)
    if config.log_odds_data:
        metrics["log_odds_map"] = _fit_log_odds_map(classifier, config, detectors)
        metrics["platt"] = metrics["log_odds_map"]["platt"]
    z = classifier.logits(val.crops)  # once, read under each rule
    rules = {rule: _fused_scores(classifier, val, rule, classifier.calibrated(z, rule))
             for rule in FUSION_RULES}
    classifier.rule = config.fusion or min(rules, key=lambda r: rules[r]["log_loss"])
    classifier.metadata["rules_on_val"] = rules
    metrics.update({"rules": rules, "rule": classifier.rule,
                    "level_weights": dict(config.level_weights), "device": str(device),
                    "n_val": len(val), "data": [str(d) for d in config.data],
                    "data_weights": list(config.data_weights),
                    "camera": config.camera})
    # the robot's classifier and its metrics beside the shared ones: robot_inspection_...
    prefix = "robot_" if config.camera == "robot" else ""
    metrics["file"] = prefix + INSPECTION_FILE
    classifier.save(config.out / metrics["file"])
    if config.camera == "robot":  # the robot's fused P(blemished), calibrated on val onions
        from robot.inspection_poses import INSPECTION_VIEWS

        shown = val.view < INSPECTION_VIEWS  # the views the robot shows an onion from
        if len(set(val.classes[shown].tolist())) == 2:
            fitted = fit_fused_calibration(
                classifier, val.subset(shown),
                {rule: classifier.calibrated(z[shown], rule) for rule in FUSION_RULES})
            metrics["fused_calibration"] = _write_fused_calibration(
                config.out, fitted, {"fitted_on": "the validation onions of the training data",
                                     "data": [str(d) for d in config.data]})
        else:
            logger.warning("the validation onions are of one class: the robot's fused "
                           "probability is left uncalibrated (`onionsort train robot-fusion`)")
    write_json(config.out / f"{prefix}inspection_metrics.json", metrics)
    return metrics


def _fit_log_odds_map(classifier, config: InspectionTrainStageConfig, detectors: dict
                      ) -> dict:
    """Fit ``classifier``'s map from a view's logit to P(its onion is blemished), which the
    ``log-odds`` fusion reads, on every view of ``config.log_odds_data`` the detector finds
    (both cameras', every split, each by its camera's detector of ``detectors``; weighted as
    validation views are); return what was fitted and on what."""
    from perception.train_inspection import fit_class_map

    views = InspectionViews.concat([inspection_views(d, "all", **detectors)
                                    for d in config.log_odds_data])
    views = views.subset(views.found.astype(bool))
    if len(set(views.classes.tolist())) < 2:
        raise ValueError(f"{', '.join(map(str, config.log_odds_data))} show onions of one "
                         "class only; the log-odds map needs good and blemished ones")
    fitted = fit_class_map(classifier.logits(views.crops), views.classes,
                           views.weights(config.level_weights))
    out = {"platt": list(fitted), "platt_on_val": list(classifier.platt),
           "data": [str(d) for d in config.log_odds_data], "views": len(views)}
    classifier.platt = fitted
    classifier.metadata["log_odds_map"] = out
    return out


def _cameras(seeds: tuple[int, ...]) -> tuple[list, list]:
    """The image maps the training views and the validation views are read through: as
    rendered (``None``), then through each seed's cameras
    (:class:`onionsort.stages.cameras.SessionCameras`; validation through the first's)."""
    from onionsort.stages.cameras import SessionCameras

    cameras = [SessionCameras(seed) for seed in seeds]
    return [None, *cameras], [None, *cameras[:1]]


def _fused(classifier, views: InspectionViews, rule: str, p: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Per onion of ``views`` (found views only): the probability under ``rule`` that fuses
    its views' probabilities ``p`` (one per row of ``views``), its class, and its key."""
    groups = defaultdict(list)
    for i, key in enumerate(views.onion):
        if views.found[i]:
            groups[key].append(i)
    keys = sorted(groups)
    fused = np.array([classifier.fuse(p[groups[k]], rule) for k in keys])
    classes = np.array([views.classes[groups[k][0]] for k in keys])
    return fused, classes, keys


def fit_fused_calibration(classifier, views: InspectionViews, p: dict[str, np.ndarray],
                          form: str = "log") -> dict[str, dict]:
    """Per fusion rule, the calibration ``(low, high, form[, powers])`` of the fused probability of
    ``classifier`` on the onions of ``views`` (found views only): each onion's fused evidence
    ``E`` (its log-odds fused at prior 1/2, uncalibrated), or under ``form`` ``"log"`` its
    size ``log(1 + |E|)`` with its sign (under ``"powers"``, its size to a power each side fits
    too), is scaled by one temperature where ``E < 0`` and by another where ``E >= 0``
    (:func:`perception.fusion.fuse`), each fitted on the onions of its side against their class
    with Platt's targets (``(n+ + 1) / (n+ + 2)`` and ``1 / (n- + 2)``, the counts of the side's
    classes, so that a side of one class gives a finite slope; :func:`fit_side_map`). The sign
    of ``E`` is kept, so on a line of prior 1/2 every call at the cost threshold 1/2 stays as it
    was; only how sure it is changes. A side with no onion keeps slope 1. ``p``: per rule, each
    row's per-view probability (:meth:`~perception.inspection.InspectionClassifier.calibrated`).

    Returns
    -------
    dict
        Per rule: ``low``, ``high``, ``form`` (under ``"powers"``, ``low_power`` and
        ``high_power``), ``onions``, ``blemished`` and the expected
        calibration error on these onions before and after (``ece_before``, ``ece_after``;
        in-sample).

    Raises
    ------
    ValueError
        If the views hold no onion of one class, or ``form`` is not one of
        :data:`CALIBRATION_FORMS`.
    """
    from perception.fusion import expected_calibration_error, fuse, log_odds

    out = {}
    for rule, probabilities in p.items():
        groups = defaultdict(list)
        for i, key in enumerate(views.onion):
            if views.found[i]:
                groups[key].append(i)
        keys = sorted(groups)
        y = np.array([views.classes[groups[k][0]] for k in keys], float)
        if not len(y) or y.min() == y.max():
            raise ValueError(f"fitting the fused calibration needs good and blemished onions "
                             f"seen; got {int(y.sum())} blemished of {len(y)}")
        args = {"prior": 0.5, "train_prior": classifier._train_prior(rule),
                "visibility": classifier.visibility}
        evidence = np.array([log_odds(probabilities[groups[k]], rule, **args) for k in keys])
        calibration = fit_side_map(evidence, y, form)
        before = np.array([fuse(probabilities[groups[k]], rule, **args) for k in keys])
        after = np.array([fuse(probabilities[groups[k]], rule, calibration=calibration,
                               **args) for k in keys])
        out[rule] = {"low": calibration[0], "high": calibration[1], "form": form,
                     **dict(zip(("low_power", "high_power"), calibration[3:], strict=False)),
                     "onions": len(y),
                     "blemished": int(y.sum()),
                     "ece_before": expected_calibration_error(before, y),
                     "ece_after": expected_calibration_error(after, y)}
    return out


def fit_side_map(evidence: np.ndarray, y: np.ndarray, form: str = "slopes") -> tuple:
    """The map :func:`fit_fused_calibration` fits from each onion's fused ``evidence`` (N,)
    (log-odds at prior 1/2) and class ``y`` (N,), as
    :func:`perception.fusion.check_calibration` gives it: ``(low, high, form)``, and under
    ``"powers"`` ``(low, high, form, low_power, high_power)``.

    Each side of ``E = 0`` is fitted alone, by log-loss against Platt's targets of its
    classes: a slope (:func:`perception.inspection.fit_temperature`) on ``E`` (``"slopes"``),
    on ``log(1 + |E|)`` (``"log"``), or on ``|E| ** k`` (``"powers"``, the power ``k`` in
    [0.05, 5] that makes the loss least, by a bounded search on its log), the sign of ``E``
    kept. A side with no onion keeps slope and power 1; a side whose onions are (nearly) all of
    one class takes its power to a bound, and a warning says so.

    Raises
    ------
    ValueError
        If ``form`` is not one of :data:`CALIBRATION_FORMS`.
    """
    if form not in CALIBRATION_FORMS:
        raise ValueError(f"form must be one of {CALIBRATION_FORMS}; got {form!r}")
    evidence, y = np.asarray(evidence, float), np.asarray(y, float)
    (low, low_power), (high, high_power) = (_fit_side(evidence[at], y[at], form, side)
                                            for at, side in ((evidence < 0, "below 0"),
                                                             (evidence >= 0, "above 0")))
    return (low, high, form, low_power, high_power) if form == "powers" else (low, high, form)


def _fit_side(e: np.ndarray, c: np.ndarray, form: str, side: str) -> tuple[float, float]:
    """The slope and power of one ``side``'s map (:func:`fit_side_map`) from its evidence ``e``
    and classes ``c``."""
    from scipy.optimize import minimize_scalar

    from perception.inspection import fit_temperature

    if not len(e) or not np.any(e):
        return 1.0, 1.0
    n_pos, n_neg = c.sum(), len(c) - c.sum()
    targets = np.where(c == 1, (n_pos + 1) / (n_pos + 2), 1 / (n_neg + 2))
    if form != "powers":
        mapped = e if form == "slopes" else np.sign(e) * np.log1p(np.abs(e))
        return float(1.0 / fit_temperature(mapped, targets)), 1.0

    def at(power: float) -> tuple[float, np.ndarray]:
        mapped = np.sign(e) * np.abs(e) ** power
        slope = float(1.0 / fit_temperature(mapped, targets))
        return slope, slope * mapped

    def loss(log_power: float) -> float:
        z = at(float(np.exp(log_power)))[1]
        return float(np.mean(np.logaddexp(0.0, z) - targets * z))

    power = float(np.exp(minimize_scalar(loss, bounds=(np.log(0.05), np.log(5.0)),
                                         method="bounded", options={"xatol": 1e-5}).x))
    if min(abs(np.log(power / bound)) for bound in (0.05, 5.0)) < 1e-3:
        logger.warning("the map's power %s runs to its bound (%.3g): the onions there are "
                       "(nearly) of one class, and each gets about one P", side, power)
    return at(power)[0], power


def _write_fused_calibration(folder: Path, fitted: dict, provenance: dict,
                             levels: dict | None = None) -> dict:
    """Write :data:`~onionsort.stages.models.ROBOT_FUSION_FILE` into ``folder`` (``levels``:
    each level's own fit, where it was fitted by level); return what was written."""
    from onionsort.stages.models import ROBOT_FUSION_FILE

    doc = {"format": 2 if levels else 1, "rules": fitted, **provenance}
    if levels:
        doc["levels"] = levels
    write_json(Path(folder) / ROBOT_FUSION_FILE, doc)
    return doc


def fit_robot_fusion_stage(config: FusionCalibrationConfig) -> dict:
    """Fit the calibration of the robot's fused P(blemished) on held-out robot onions
    (:func:`fit_fused_calibration`, each view read by the robot's inspection classifier and
    cropped round the detector's box, as at inference) and write
    :data:`~onionsort.stages.models.ROBOT_FUSION_FILE` into ``config.out``, which
    :meth:`~onionsort.stages.models.PerceptionModels.load` applies to the robot's classifier.
    With ``config.by_level`` each difficulty level's onions fit a calibration of its own too
    (of the form ``config.level_forms`` gives the level, else ``config.form``), which
    :meth:`~onionsort.stages.models.PerceptionModels.at_level` applies on a line of that
    level. Returns what was written.

    Raises
    ------
    ValueError
        If the data hold no robot view, no onion of one class, or (by level) a level whose
        onions are all of one class, or none of a level ``config.level_forms`` names.
    """
    from onionsort.stages.models import PerceptionModels
    from perception.fusion import FUSION_RULES

    log_config("train robot-fusion", config)
    models = PerceptionModels.load(config.models, config.device)
    if models.robot_inspection is None:
        raise ValueError(f"{models.folder} has no robot inspection classifier to calibrate")
    clf = models.robot_inspection
    for rule in FUSION_RULES:  # fitted on the evidence as fused, never on top of a calibration
        clf.set_fused_calibration(rule, None)
    parts = [inspection_views(d, config.split, detector=models.detector,
                              robot_detector=models.robot_detector, allow_empty=True)
             for d in config.data]
    views = InspectionViews.concat(parts)
    from robot.inspection_poses import INSPECTION_VIEWS

    shown = INSPECTION_VIEWS if config.views is None else config.views
    keep = (views.source == "robot") & views.found.astype(bool) & (views.view < shown)
    views = views.subset(keep)
    if not len(views):
        raise ValueError(f"{', '.join(map(str, config.data))} hold no robot view of an onion "
                         f"in split {config.split!r}; render them with `onionsort dataset "
                         "--robot-onions N`")
    if missing := sorted(set(config.level_forms) - set(views.level.tolist())):
        raise ValueError(f"level_forms names {missing}; the data hold no robot onion there")
    z = clf.logits(views.crops)
    p = {rule: clf.calibrated(z, rule) for rule in FUSION_RULES}
    fitted = fit_fused_calibration(clf, views, p, config.form)
    levels = {}
    for level in sorted(set(views.level.tolist()), key=_level_order) if config.by_level else ():
        at = views.level == level
        try:
            levels[str(level)] = fit_fused_calibration(
                clf, views.subset(at), {rule: q[at] for rule, q in p.items()},
                config.level_forms.get(str(level), config.form))
        except ValueError as exc:
            raise ValueError(f"level {level!r}: {exc}") from None
    Path(config.out).mkdir(parents=True, exist_ok=True)
    return _write_fused_calibration(config.out, fitted, {
        "fitted_on": "held-out robot onions", "data": [str(d) for d in config.data],
        "split": config.split, "views": shown, "form": config.form,
        **({"level_forms": dict(config.level_forms)} if config.level_forms else {}),
        "models": models.describe()}, levels)


def _fused_scores(classifier, views: InspectionViews, rule: str, p: np.ndarray) -> dict:
    """Log-loss and accuracy of the fused call on the onions of ``views``."""
    fused, y, _ = _fused(classifier, views, rule, p)
    q = np.clip(fused, 1e-6, 1 - 1e-6)
    return {"log_loss": float(-np.mean(y * np.log(q) + (1 - y) * np.log1p(-q))),
            "accuracy": float(np.mean((fused >= 0.5) == (y == 1))), "n_onions": len(y)}


def measure_inspection(models, root: Path | str, split: str = "test", *,
                       threshold: float | None = None, views: int | None = None,
                       image_map=None) -> dict:
    """The inspection on a dataset split, per difficulty level and source.

    For each level: how often the detector finds the onion; the accuracy of each view alone
    (its rot call against the rot it shows, and its class call against the onion's class,
    with the way it errs: the share of a good onion's views called blemished and of a
    blemished onion's views called good); and, for each fusion rule, the fused call on each
    onion (the robot's views of it, the first ``views`` of them if given; the sorter's views
    of it in a session) at ``threshold`` (the task's cost threshold by default): accuracy,
    precision, recall, expected calibration error (``ece``) beside the median
    (``ece_by_chance``) and the 90th percentile (``ece_by_chance_90``) of what a perfectly
    calibrated model shows by chance on the same onions
    (:func:`perception.fusion.calibration_within_chance`), and the points of the
    precision-recall curve. ``image_map`` changes each view as it is read
    (:func:`inspection_views`).
    """
    from onionsort.configs.common import sorting_threshold
    from perception.fusion import (
        FUSION_RULES,
        calibration_within_chance,
        chance_calibration_error,
        expected_calibration_error,
        precision_recall_curve,
    )

    threshold = sorting_threshold() if threshold is None else threshold
    data = inspection_views(root, split, detector=models.detector, allow_empty=True,
                            image_map=image_map, robot_detector=models.robot_detector)
    if views is not None:
        keep = (data.source != "robot") | (data.view < views)
        data = data.subset(keep)
    # each view read by the classifier of its camera (the robot's own, where there is one)
    readers = {source: models.inspection_for("robot" if source == "robot" else "sorter")
               for source in ("robot", "human")}
    p_view = {rule: np.zeros(len(data)) for rule in FUSION_RULES}
    seen = data.found.astype(bool)  # an empty set's columns are float
    for source, clf in readers.items():
        mine = seen & (data.source == source)
        if mine.any():
            z = clf.logits(data.crops[mine])
            for rule in FUSION_RULES:
                p_view[rule][mine] = clf.calibrated(z, rule)
    p_rot, p_class = p_view["noisy-or"], p_view["log-odds"]  # rot in view; onion's class
    out: dict = {"threshold": threshold, "rule": readers["human"].rule,
                 "robot_rule": readers["robot"].rule, "levels": {}}
    for level in sorted(set(data.level), key=_level_order):
        at = data.level == level
        report = {}
        for source in ("robot", "human"):
            mine = at & (data.source == source)
            if not mine.any():
                continue
            found = mine & data.found
            clear = found & (data.labels >= 0)
            row = {"views": int(mine.sum()), "found": float(found.sum() / mine.sum()),
                   "rot_accuracy": _mean((p_rot[clear] >= 0.5) == (data.labels[clear] == 1)),
                   "rot_ece": (expected_calibration_error(p_rot[clear], data.labels[clear])
                               if clear.any() else None),
                   "view_accuracy": _mean((p_class[found] >= 0.5)
                                          == (data.classes[found] == 1)),
                   # which way the class call per view errs
                   "good_views_called_blemished": _mean(
                       p_class[found & (data.classes == 0)] >= 0.5),
                   "blemished_views_called_good": _mean(
                       p_class[found & (data.classes == 1)] < 0.5),
                   "fused": {}}
            if source == "robot":
                row["view_accuracy_by_view"] = {
                    int(v): _mean((p_class[found & (data.view == v)] >= 0.5)
                                  == (data.classes[found & (data.view == v)] == 1))
                    for v in sorted(set(data.view[found]))}
            subset = data.subset(mine)
            reader = readers[source]
            if source == "robot":  # its fused probability calibrated for the level's line
                reader = models.at_level(str(level)).inspection_for("robot")
                row["fused_calibration"] = models.fused_calibration_of(str(level))
            for rule in FUSION_RULES:
                fused, y, _ = _fused(reader, subset, rule, p_view[rule][mine])
                if not len(y):
                    continue
                called = fused >= threshold
                tp = int(np.sum(called & (y == 1)))
                fp = int(np.sum(called & (y == 0)))
                fn = int(np.sum(~called & (y == 1)))
                precision, recall, cut = precision_recall_curve(fused, y)
                row["fused"][rule] = {
                    "onions": len(y), "blemished": tp + fn, "called_blemished": tp + fp,
                    "accuracy": float(np.mean(called == (y == 1))),
                    "precision": tp / (tp + fp) if tp + fp else 0.0,
                    "recall": tp / (tp + fn) if tp + fn else 0.0,
                    "ece": expected_calibration_error(fused, y),
                    "ece_by_chance": chance_calibration_error(fused),
                    "ece_by_chance_90": calibration_within_chance(fused, y)[
                        "chance_quantile"],
                    "pr_curve": {"precision": precision.round(4).tolist(),
                                 "recall": recall.round(4).tolist(),
                                 "threshold": cut.round(5).tolist()}}
            report[source] = row
        out["levels"][str(level)] = report
    return out


def _mean(values) -> float | None:
    values = np.asarray(values)
    return float(values.mean()) if values.size else None


def _level_order(level: str) -> tuple[int, str]:
    from robot.difficulty import DIFFICULTY_LEVELS

    names = list(DIFFICULTY_LEVELS)
    return (names.index(level) if level in names else len(names), str(level))
