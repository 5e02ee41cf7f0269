"""``onionsort train``: train perception models on a dataset from ``onionsort dataset``.

Examples
--------
    onionsort dataset --frames 3000 --out runs/data
    onionsort train state-classifier --data runs/data --out runs/perception
    onionsort train detector --data runs/data --out runs/perception
    onionsort train detector --data runs/data --out runs/perception --resume
"""

from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["register"]


def register(subparsers) -> None:
    """Add the ``train`` subcommand and its models."""
    parser = subparsers.add_parser(
        "train", help="train perception models", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    models = parser.add_subparsers(dest="model", metavar="MODEL", required=True)
    sc = models.add_parser("state-classifier",
                           help="the SA-Net-style classifier: onion/hand location, occluded")
    det = models.add_parser("detector", help="the YOLO-style onion detector (good / blemished)")
    for p, epochs, batch_size in ((sc, 12, 32), (det, 24, 16)):
        p.add_argument("--data", type=Path, required=True, help="dataset folder")
        p.add_argument("--out", type=Path, required=True, help="run folder for the checkpoints")
        p.add_argument("--epochs", type=int, default=epochs)
        p.add_argument("--batch-size", type=int, default=batch_size)
        p.add_argument("--seed", type=int, default=0)
    sc.add_argument("--depth-dropout", type=float, default=0.5,
                    help="probability that a training step's depth is zeroed, so the model "
                         "also reads steps without depth (0.5)")
    sc.set_defaults(func=run_state_classifier)
    det.add_argument("--images-per-epoch", type=int, default=1600)
    det.add_argument("--resume", action="store_true",
                     help="continue the run in --out from its last checkpoint")
    det.set_defaults(func=run_detector)


def run_state_classifier(args: argparse.Namespace) -> int:
    from onionsort.stages.train import ClassifierTrainConfig, train_state_classifier

    metrics = train_state_classifier(ClassifierTrainConfig(
        data=args.data, out=args.out, epochs=args.epochs, batch_size=args.batch_size,
        seed=args.seed, depth_dropout=args.depth_dropout))
    for key, label in (("test", ""), ("test_without_depth", " without depth")):
        if metrics.get(key):
            print(f"state classifier, test split{label}: "
                  + ", ".join(f"{k} {v:.3f}" for k, v in metrics[key].items()))
    print(f"wrote {args.out / 'state_classifier.pt'}")
    return 0


def run_detector(args: argparse.Namespace) -> int:
    from onionsort.stages.train import DetectorTrainConfig, train_detector

    test = train_detector(DetectorTrainConfig(
        data=args.data, out=args.out, epochs=args.epochs, images_per_epoch=args.images_per_epoch,
        batch_size=args.batch_size, seed=args.seed, resume=args.resume))["test"]
    print(f"detector, test split: mAP@0.5 {test['map50']:.3f}, mAP@0.5:0.95 "
          f"{test['map50_95']:.3f}")
    print(f"wrote {args.out / 'detector.pt'}")
    return 0
