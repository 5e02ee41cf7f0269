"""``onionsort calibrate``, ``onionsort eval-perception`` and ``onionsort perceive``.

- ``calibrate`` runs the detector and the state classifier on the held-out (test) split of a
  labelled dataset, measures the confusion of every factor of the state and of the action, and
  writes the calibration the learners read (``calibration.json``), the observation model it
  gives (``observation_model.npz``, ``O[s, a, o]``) and a plot of each confusion matrix.
- ``eval-perception`` measures both models on a dataset split: mAP of the detector, accuracy of
  each factor on unoccluded steps, recall of occluded steps.
- ``perceive`` adds the perception topics to recorded sessions, so they can be learned from.

Models default to the ones shipped with the package (``onionsort/models``).

Examples
--------
    onionsort dataset --frames 1500 --seed 1 --out runs/heldout
    onionsort calibrate --data runs/heldout --split all --out runs/calibration
    onionsort eval-perception --data runs/heldout --json
    onionsort record --sessions 12 --out runs/rec
    onionsort perceive runs/rec/*.mcap
"""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path

__all__ = ["register"]

logger = logging.getLogger(__name__)


def _models_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--models", type=Path, default=None,
                        help="folder with state_classifier.pt and detector.pt (default: the "
                             "models shipped with onionsort)")


def register(subparsers) -> None:
    """Add ``calibrate``, ``eval-perception`` and ``perceive``."""
    cal = subparsers.add_parser(
        "calibrate", help="measure perception's confusion matrices -> the observation model",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    cal.add_argument("--data", type=Path, required=True, help="labelled dataset folder")
    cal.add_argument("--split", default="test",
                     help="the held-out split to use: train, val, test or all (test)")
    cal.add_argument("--out", type=Path, required=True, help="folder for the calibration")
    cal.add_argument("--smoothing", type=float, default=1.0,
                     help="additive smoothing of the confusion counts (1.0)")
    _models_argument(cal)
    cal.set_defaults(func=run_calibrate)

    ev = subparsers.add_parser(
        "eval-perception", help="measure the detector and the state classifier on a dataset",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ev.add_argument("--data", type=Path, required=True, help="labelled dataset folder")
    ev.add_argument("--split", default="test",
                    help="split to evaluate on: train, val, test or all (test)")
    ev.add_argument("--json", action="store_true", help="print one JSON object")
    _models_argument(ev)
    ev.set_defaults(func=run_eval)

    per = subparsers.add_parser(
        "perceive", help="add perception topics (detections, state estimates) to sessions",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    per.add_argument("sessions", type=Path, nargs="+", metavar="SESSION.mcap")
    per.add_argument("--replace", action="store_true",
                     help="perceive sessions that already hold perception topics again")
    _models_argument(per)
    per.set_defaults(func=run_perceive)


def run_calibrate(args: argparse.Namespace) -> int:
    import numpy as np

    from onionsort.pipeline import PerceptionModels, evaluate_dataset
    from onionsort.plots import confusion_figure

    if args.smoothing < 0:
        raise ValueError(f"--smoothing must be >= 0; got {args.smoothing}")
    models = PerceptionModels.load(args.models)
    calibration, metrics = evaluate_dataset(models, args.data, args.split)
    calibration = calibration.with_smoothing(args.smoothing)
    args.out.mkdir(parents=True, exist_ok=True)
    path = calibration.save(args.out / "calibration.json", extra={
        "data": str(args.data), "split": args.split, "models": models.describe(),
        "metrics": metrics})
    model = calibration.observation_model()
    np.savez_compressed(args.out / "observation_model.npz", probs=model.probs)
    confusion_figure(calibration, args.out / "confusion.png")
    print(f"calibrated on {metrics['n_steps']} steps of {args.data} ({args.split}), "
          f"{calibration.n_observed} called unoccluded")
    for name, matrix in calibration.factors.items():
        print(f"  {name:13s} accuracy {matrix.accuracy:.3f}")
    print(f"effective noise: state error rate {calibration.state_error_rate:.3f}, "
          f"(state, action) error rate {calibration.pair_error_rate:.3f} "
          "(the paper estimated about 0.30 for its camera)")
    print(f"wrote {path}, {args.out / 'observation_model.npz'}, {args.out / 'confusion.png'}")
    return 0


def run_eval(args: argparse.Namespace) -> int:
    from onionsort.pipeline import PerceptionModels, detector_map, evaluate_dataset

    models = PerceptionModels.load(args.models)
    _, metrics = evaluate_dataset(models, args.data, args.split)
    maps = detector_map(models, args.data, args.split)
    result = {"map50": maps["all"]["map50"], "map50_95": maps["all"]["map50_95"],
              "accuracy": metrics["accuracy"], "occlusion_recall": metrics["occlusion_recall"],
              "occlusion_precision": metrics["occlusion_precision"],
              "map_by_view": maps, "n_steps": metrics["n_steps"], "split": args.split}
    if args.json:
        print(json.dumps(result))
        return 0
    print(f"detector: mAP@0.5 {result['map50']:.3f}, mAP@0.5:0.95 {result['map50_95']:.3f}")
    for view, m in maps.items():
        if view != "all":
            print(f"  {view:10s} mAP@0.5 {m['map50']:.3f}, mAP@0.5:0.95 {m['map50_95']:.3f}")
    print("state classifier, unoccluded steps: " + ", ".join(
        f"{k} {v:.3f}" for k, v in metrics["accuracy"].items()))
    print(f"occluded steps: recall {metrics['occlusion_recall']:.3f}, precision "
          f"{metrics['occlusion_precision']:.3f} ({metrics['n_steps']} steps)")
    return 0


def run_perceive(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from onionsort.pipeline import PerceptionModels, perceive_session

    missing = [str(p) for p in args.sessions if not p.is_file()]
    if missing:
        raise FileNotFoundError(f"no such session file(s): {', '.join(missing)}")
    models = PerceptionModels.load(args.models)
    for path in tqdm(args.sessions, desc="perceive", unit="session"):
        steps = perceive_session(models, path, replace=args.replace)
        occluded = sum(s.occluded for s in steps)
        logger.info("%s: %d steps, %d called occluded", path, len(steps), occluded)
    print(f"perceived {len(args.sessions)} session(s); perception topics added in place")
    return 0
