"""``onionsort train``: train perception models on a dataset from ``onionsort dataset``.

Examples
--------
    onionsort dataset --frames 3000 --out runs/data
    onionsort train state-classifier --data runs/data --out runs/perception
    onionsort train detector --data runs/data --out runs/perception
    onionsort train detector --data runs/data --out runs/perception --resume
    onionsort train inspection --data runs/data --out runs/perception
    onionsort train robot-fusion --data runs/heldout-a --data runs/heldout-b \\
        --models runs/perception --out runs/perception
    onionsort train state-classifier --data runs/data --out runs/plain --no-augment
    onionsort train detector --data runs/lab --data runs/data --data-weights 3,1 \
        --init runs/perception/detector.pt --epochs 6 --lr 5e-4 --out runs/lab-models

Every model is trained with photometric augmentation unless ``--no-augment``: each training
sample is seen through a camera of its own (``perception.photometric``); evaluation never is.

``robot-fusion`` trains no network: it fits the calibration of the robot's fused P(blemished)
(a temperature on each side of the fused evidence's 0: monotone, and the call unchanged) on
held-out robot onions and writes ``robot_fusion_calibration.json``, which the robot's
inspection then applies. ``train inspection --camera robot`` writes one too, fitted on its
validation onions.
"""

from __future__ import annotations

import argparse

from onionsort.commands import add_command
from onionsort.configs import config_from_args
from onionsort.configs.inspection import FusionCalibrationConfig, InspectionTrainStageConfig
from onionsort.configs.train import ClassifierTrainConfig, DetectorTrainConfig

__all__ = ["register"]


def register(subparsers) -> None:
    """Add the ``train`` subcommand and its models."""
    parser = subparsers.add_parser(
        "train", help="train perception models", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    models = parser.add_subparsers(dest="model", metavar="MODEL", required=True)
    add_command(models, "state-classifier", None,
                "the SA-Net-style classifier: onion/hand location, occluded",
                ClassifierTrainConfig, run_state_classifier)
    add_command(models, "detector", None, "the YOLO-style onion detector (good / blemished)",
                DetectorTrainConfig, run_detector)
    add_command(models, "inspection", None,
                "the inspection classifier: does a view of the held onion show rot",
                InspectionTrainStageConfig, run_inspection)
    add_command(models, "robot-fusion", None,
                "calibrate the robot's fused P(blemished) on held-out onions",
                FusionCalibrationConfig, run_robot_fusion)


def run_state_classifier(args: argparse.Namespace) -> int:
    from onionsort.stages.train import train_state_classifier

    metrics = train_state_classifier(config_from_args(ClassifierTrainConfig, args))
    for key, label in (("test", ""), ("test_without_depth", " without depth")):
        if metrics.get(key):
            print(f"state classifier, test split{label}: "
                  + ", ".join(f"{k} {v:.3f}" for k, v in metrics[key].items()))
    print(f"wrote {args.out / 'state_classifier.pt'}")
    return 0


def run_detector(args: argparse.Namespace) -> int:
    from onionsort.stages.train import train_detector

    test = train_detector(config_from_args(DetectorTrainConfig, args))["test"]
    print(f"detector, test split: mAP@0.5 {test['map50']:.3f}, mAP@0.5:0.95 "
          f"{test['map50_95']:.3f}")
    print(f"wrote {args.out / 'detector.pt'}")
    return 0


def run_inspection(args: argparse.Namespace) -> int:
    from onionsort.stages.inspection import train_inspection_stage

    metrics = train_inspection_stage(config_from_args(InspectionTrainStageConfig, args))
    val = metrics["val"]
    print(f"inspection classifier, val split: rot call accuracy {val['accuracy']:.3f} on "
          f"{val['n']} views, temperature {metrics['temperature']:.3f}")
    for rule, m in metrics["rules"].items():
        print(f"  fused by {rule}: accuracy {m['accuracy']:.3f}, log-loss {m['log_loss']:.3f} "
              f"on {m['n_onions']} onions")
    print(f"fusion rule: {metrics['rule']}; wrote {args.out / metrics['file']}")
    return 0


def run_robot_fusion(args: argparse.Namespace) -> int:
    from onionsort.stages.inspection import fit_robot_fusion_stage

    doc = fit_robot_fusion_stage(config_from_args(FusionCalibrationConfig, args))
    for rule, fit in doc["rules"].items():
        print(f"  fused by {rule}: {fit['form']} {fit['low']:.3f} below 0, {fit['high']:.3f} "
              f"above, on "
              f"{fit['onions']} onions "
              f"({fit['blemished']} blemished); ECE here {fit['ece_before']:.3f} -> "
              f"{fit['ece_after']:.3f}")
    print(f"wrote {args.out / 'robot_fusion_calibration.json'}")
    return 0
