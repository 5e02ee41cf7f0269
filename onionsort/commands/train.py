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
from pathlib import Path

from onionsort.commands._args import add_device_argument, add_models_argument

__all__ = ["register"]


def register(subparsers) -> None:
    """Add the ``train`` subcommand and its models."""
    from onionsort.commands._args import FUSION_RULES, INSPECTION_CAMERAS

    parser = subparsers.add_parser(
        "train", help="train perception models", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    models = parser.add_subparsers(dest="model", metavar="MODEL", required=True)
    sc = models.add_parser("state-classifier",
                           help="the SA-Net-style classifier: onion/hand location, occluded")
    det = models.add_parser("detector", help="the YOLO-style onion detector (good / blemished)")
    ins = models.add_parser("inspection",
                            help="the inspection classifier: does a view of the held onion "
                                 "show rot")
    for p, epochs, batch_size in ((sc, 12, 32), (det, 24, 16), (ins, 30, 128)):
        p.add_argument("--data", type=Path, required=True, action="append",
                       help="dataset folder (repeat it to pool several, e.g. a lab's frames "
                            "from `onionsort label import` and rendered ones)")
        p.add_argument("--data-weights", type=_weights, default=(), metavar="W,W,...",
                       help="how many times each --data's training frames count, in their "
                            "order, e.g. 3,1 (1 each)")
        p.add_argument("--out", type=Path, required=True, help="run folder for the checkpoints")
        p.add_argument("--epochs", type=int, default=epochs)
        p.add_argument("--batch-size", type=int, default=batch_size)
        p.add_argument("--seed", type=int, default=0)
        p.add_argument("--augment", action=argparse.BooleanOptionalAction, default=True,
                       help="see each training sample through a camera of its own (white "
                            "balance, exposure, tone curve, defocus, noise, JPEG), never at "
                            "evaluation (default: on)")
        add_device_argument(p)
    ins.add_argument("--detector", type=Path, default=None,
                     help="folder of the detector.pt that finds the onion in the validation "
                          "views (default: the shipped one)")
    ins.add_argument("--level-weights", type=_level_weights, default={},
                     help="weights of difficulty levels, e.g. clean=2,hard=1 (each 1 by "
                          "default)")
    ins.add_argument("--fusion", choices=FUSION_RULES, default=None,
                     help="the classifier's fusion rule (default: the one of lower log-loss on "
                          "the validation onions)")
    ins.add_argument("--camera", choices=INSPECTION_CAMERAS, default="both",
                     help="whose views to learn from: both (the sorter's and the robot's; "
                          "writes inspection_classifier.pt, which both read) or robot (the "
                          "Sawyer's only; writes robot_inspection_classifier.pt, which its "
                          "inspection then reads instead)")
    ins.add_argument("--visibility", type=float, default=None,
                     help="the chance that a view of a blemished onion shows its rot, as "
                          "noisy-or fusion assumes it (default: the share measured on the "
                          "training views)")
    ins.set_defaults(func=run_inspection)
    sc.add_argument("--depth-dropout", type=float, default=0.5,
                    help="probability that a training step's depth is zeroed, so the model "
                         "also reads steps without depth (0.5)")
    sc.set_defaults(func=run_state_classifier)
    det.add_argument("--images-per-epoch", type=int, default=1600)
    for p, what in ((det, "a detector.pt"), (sc, "a state_classifier.pt"),
                    (ins, "an inspection_classifier.pt")):
        p.add_argument("--init", type=Path, default=None, metavar="CHECKPOINT",
                       help=f"{what} to fine-tune instead of training from scratch")
    det.add_argument("--lr", type=float, default=2e-3, help="peak learning rate (0.002)")
    for p in (sc, ins):
        p.add_argument("--lr", type=float, default=3e-3, help="peak learning rate (0.003)")
    det.add_argument("--resume", action="store_true",
                     help="continue the run in --out from its last checkpoint")
    det.set_defaults(func=run_detector)
    fus = models.add_parser("robot-fusion",
                            help="calibrate the robot's fused P(blemished) on held-out onions")
    fus.add_argument("--data", type=Path, required=True, action="append",
                     help="held-out dataset folder with robot onions (repeat it to pool "
                          "several); never the data the calibration is then measured on")
    fus.add_argument("--split", choices=("train", "val", "test", "all"), default="all",
                     help="the split whose robot onions fit it (all)")
    fus.add_argument("--views", type=int, default=None,
                     help="the first VIEWS views of each onion (default: as many as the "
                          "robot takes)")
    fus.add_argument("--out", type=Path, required=True,
                     help="folder to write robot_fusion_calibration.json into (the models "
                          "folder, for the robot to apply it)")
    add_models_argument(fus)
    add_device_argument(fus)
    fus.set_defaults(func=run_robot_fusion)


def run_state_classifier(args: argparse.Namespace) -> int:
    from onionsort.stages.train import ClassifierTrainConfig, train_state_classifier

    metrics = train_state_classifier(ClassifierTrainConfig(
        data=args.data, out=args.out, epochs=args.epochs, batch_size=args.batch_size,
        seed=args.seed, depth_dropout=args.depth_dropout, device=args.device,
        augment=args.augment, init=args.init, data_weights=args.data_weights, lr=args.lr))
    for key, label in (("test", ""), ("test_without_depth", " without depth")):
        if metrics.get(key):
            print(f"state classifier, test split{label}: "
                  + ", ".join(f"{k} {v:.3f}" for k, v in metrics[key].items()))
    print(f"wrote {args.out / 'state_classifier.pt'}")
    return 0


def run_detector(args: argparse.Namespace) -> int:
    from onionsort.stages.train import DetectorTrainConfig, train_detector

    test = train_detector(DetectorTrainConfig(
        data=tuple(args.data), out=args.out, epochs=args.epochs,
        images_per_epoch=args.images_per_epoch, batch_size=args.batch_size, seed=args.seed,
        resume=args.resume, device=args.device, init=args.init, lr=args.lr,
        data_weights=args.data_weights, augment=args.augment))["test"]
    print(f"detector, test split: mAP@0.5 {test['map50']:.3f}, mAP@0.5:0.95 "
          f"{test['map50_95']:.3f}")
    print(f"wrote {args.out / 'detector.pt'}")
    return 0


def _weights(text: str) -> tuple[int, ...]:
    """Positive integers joined by commas, for argparse ``type=``."""
    try:
        weights = tuple(int(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected positive integers joined by commas, e.g. 3,1; got {text!r}") from None
    if not weights or min(weights) < 1:
        raise argparse.ArgumentTypeError(
            f"expected positive integers joined by commas, e.g. 3,1; got {text!r}")
    return weights


def _level_weights(text: str) -> dict[str, float]:
    """``level=weight`` pairs joined by commas, for argparse ``type=``."""
    from robot.difficulty import DIFFICULTY_LEVELS

    out = {}
    for part in filter(None, (x.strip() for x in text.split(","))):
        level, _, weight = part.partition("=")
        if level not in DIFFICULTY_LEVELS:
            raise argparse.ArgumentTypeError(
                f"unknown level {level!r} in {text!r}; the levels are "
                f"{', '.join(DIFFICULTY_LEVELS)}")
        try:
            out[level] = float(weight)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected level=weight pairs, e.g. clean=2; got {part!r}") from None
        if not out[level] > 0:
            raise argparse.ArgumentTypeError(f"a level's weight must be > 0; got {part!r}")
    return out


def run_inspection(args: argparse.Namespace) -> int:
    from onionsort.stages.inspection import InspectionTrainStageConfig, train_inspection_stage

    metrics = train_inspection_stage(InspectionTrainStageConfig(
        data=tuple(args.data), out=args.out, epochs=args.epochs, batch_size=args.batch_size,
        seed=args.seed, detector=args.detector, level_weights=args.level_weights,
        device=args.device, fusion=args.fusion,
        visibility=args.visibility, camera=args.camera, augment=args.augment, init=args.init,
        data_weights=args.data_weights, lr=args.lr))
    val = metrics["val"]
    print(f"inspection classifier, val split: rot call accuracy {val['accuracy']:.3f} on "
          f"{val['n']} views, temperature {metrics['temperature']:.3f}")
    for rule, m in metrics["rules"].items():
        print(f"  fused by {rule}: accuracy {m['accuracy']:.3f}, log-loss {m['log_loss']:.3f} "
              f"on {m['n_onions']} onions")
    print(f"fusion rule: {metrics['rule']}; wrote {args.out / metrics['file']}")
    return 0


def run_robot_fusion(args: argparse.Namespace) -> int:
    from onionsort.stages.inspection import FusionCalibrationConfig, fit_robot_fusion_stage

    doc = fit_robot_fusion_stage(FusionCalibrationConfig(
        data=tuple(args.data), out=args.out, split=args.split, models=args.models,
        views=args.views, device=args.device))
    for rule, fit in doc["rules"].items():
        print(f"  fused by {rule}: slopes {fit['low']:.3f} below 0, {fit['high']:.3f} above, on "
              f"{fit['onions']} onions "
              f"({fit['blemished']} blemished); ECE here {fit['ece_before']:.3f} -> "
              f"{fit['ece_after']:.3f}")
    print(f"wrote {args.out / 'robot_fusion_calibration.json'}")
    return 0
