"""``onionsort train``: train perception models on a dataset from ``onionsort dataset``.

``MODEL`` is one of the state classifier, the detector, the inspection classifier, or
``robot-fusion``, the calibration of the robot's fused inspection; each model's ``--help``
says what it writes. Every network is trained with photometric augmentation unless
``--no-augment``: each training sample is seen through a camera of its own
(``perception.photometric``); evaluation never is. ``--data`` may be repeated to pool several
datasets (a lab's frames from ``onionsort label import`` and rendered ones), each weighted by
``--data-weights``; ``--init`` fine-tunes a checkpoint instead of training from scratch.

Examples
--------
    onionsort dataset --frames 3000 --out runs/data
    onionsort train state-classifier --data runs/data --out runs/perception
    onionsort train detector --data runs/data --out runs/perception
    onionsort train inspection --data runs/data --out runs/perception
    onionsort train detector --data runs/lab --data runs/data --data-weights 3,1 \\
        --init runs/perception/detector.pt --epochs 6 --lr 5e-4 --out runs/lab-models
"""

from __future__ import annotations

import argparse

from onionsort.commands import add_command, add_group
from onionsort.configs import config_from_args
from onionsort.configs.inspection import FusionCalibrationConfig, InspectionTrainStageConfig
from onionsort.configs.train import ClassifierTrainConfig, DetectorTrainConfig

__all__ = ["register"]


STATE_CLASSIFIER = """``onionsort train state-classifier``: the SA-Net-style classifier.

It reads the onion's and the hand's locations, the sorter's action, whether an onion waits
at the stop gate, and whether the camera was blocked, off a step's colour frames and depth
(zeroed at random in training, ``--depth-dropout``, so the model also reads sessions without
depth), and keeps the epoch of best validation score. Writes ``state_classifier.pt`` into
``--out`` and prints each head's accuracy on the test split, with and without depth.

Examples
--------
    onionsort train state-classifier --data runs/data --out runs/perception
    onionsort train state-classifier --data runs/data --out runs/plain --no-augment
    onionsort train state-classifier --data runs/lab --data runs/data --data-weights 3,1 \\
        --init onionsort/models/state_classifier.pt --lr 3e-4 --out runs/lab-models
"""

DETECTOR = """``onionsort train detector``: the YOLO-style, anchor-free onion detector.

It finds good and blemished onions in the main camera's frames and the inspection views,
trained from scratch (or from ``--init``) on ``--images-per-epoch`` images an epoch, and
keeps the epoch of best validation score. Writes ``detector.pt`` into ``--out`` (with a
checkpoint each epoch, which ``--resume`` continues from) and prints its COCO mAP on the test
split. ``--through-cameras`` also trains on the camera frames seen through other cameras, the
ones ``eval-perception --camera-shift`` draws, at the frames' own resolution.

Examples
--------
    onionsort train detector --data runs/data --out runs/perception
    onionsort train detector --data runs/data --out runs/perception --resume
    onionsort train detector --data runs/lab --data runs/data --data-weights 3,1 \\
        --init runs/perception/detector.pt --epochs 6 --lr 5e-4 --out runs/lab-models
    onionsort train detector --data runs/data --through-cameras 8801,8802 \\
        --init runs/perception/detector.pt --epochs 8 --lr 7e-4 --out runs/across
"""

INSPECTION = """``onionsort train inspection``: the classifier of a held onion's views.

It learns whether a view of the onion at the inspection spot (the sorter's) or in the
Sawyer's gripper (the robot's) shows rot, calibrates its probability with a temperature, and
chooses how the views of one onion are fused (``--fusion``, by default the rule of lower
log-loss on the validation onions). With ``--camera both`` it writes
``inspection_classifier.pt``, which both inspections read; with ``--camera robot``
``robot_inspection_classifier.pt`` and ``robot_fusion_calibration.json``, which the Sawyer's
inspection then reads instead; with ``--camera sorter`` ``inspection_classifier.pt`` learnt,
validated and calibrated on the sorter's views alone (for a models folder whose robot has its
own). The validation views are found with ``--detector``'s model (the Sawyer's by its
``robot_detector.pt`` where the folder has one), and with ``--crops detected`` the training
crops are cut round the boxes it finds.
``--through-cameras`` also trains on each view seen through other cameras, the ones
``eval-perception --camera-shift`` draws.

Examples
--------
    onionsort train inspection --data runs/data --out runs/perception
    onionsort train inspection --data runs/data-mix --level-weights clean=1,hard=2 \\
        --fusion noisy-or --out runs/perception
    onionsort train inspection --data runs/data-robot --camera robot --fusion noisy-or \\
        --visibility 0.3 --out runs/perception
    onionsort train inspection --data runs/data --camera sorter --through-cameras 8801,8802 \\
        --init runs/perception/inspection_classifier.pt --lr 3e-4 --epochs 8 --out runs/across
"""

ROBOT_FUSION = """``onionsort train robot-fusion``: calibrate the robot's fused P(blemished).

It trains no network: it fits a temperature on each side of the fused evidence's 0 (monotone,
so no call changes) on held-out robot onions, and writes ``robot_fusion_calibration.json``
into ``--out``, which the robot's inspection then applies. With ``--by-level`` each
difficulty level in the data fits one of its own too, which the robot applies on a line of that
level (the pooled one elsewhere). Give it data that the calibration is not then measured on.

Examples
--------
    onionsort train robot-fusion --data runs/heldout-a --data runs/heldout-b \\
        --models runs/perception --out runs/perception
    onionsort train robot-fusion --data runs/fit-clean --data runs/fit-hard --by-level \\
        --out runs/perception
    onionsort train robot-fusion --data runs/heldout-a --split val --views 4 --out runs/models
"""


def register(subparsers) -> None:
    """Add the ``train`` subcommand and its models."""
    models = add_group(subparsers, "train", __doc__, "train perception models", dest="model",
                       metavar="MODEL")
    add_command(models, "state-classifier", STATE_CLASSIFIER,
                "the SA-Net-style classifier: onion/hand location, occluded",
                ClassifierTrainConfig, run_state_classifier)
    add_command(models, "detector", DETECTOR, "the YOLO-style onion detector (good / blemished)",
                DetectorTrainConfig, run_detector)
    add_command(models, "inspection", INSPECTION,
                "the inspection classifier: does a view of the held onion show rot",
                InspectionTrainStageConfig, run_inspection)
    add_command(models, "robot-fusion", ROBOT_FUSION,
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
    for where, rules in (("all levels", doc["rules"]), *doc.get("levels", {}).items()):
        if "levels" in doc:
            print(where)
        for rule, fit in rules.items():
            powers = ((f" |E|^{fit['low_power']:.3f}", f" E^{fit['high_power']:.3f}")
                      if "low_power" in fit else ("", ""))
            print(f"  fused by {rule}: {fit['form']} {fit['low']:.3f}{powers[0]} below 0, "
                  f"{fit['high']:.3f}{powers[1]} above, on {fit['onions']} onions "
                  f"({fit['blemished']} blemished); ECE here {fit['ece_before']:.3f} -> "
                  f"{fit['ece_after']:.3f}")
    print(f"wrote {args.out / 'robot_fusion_calibration.json'}")
    return 0
