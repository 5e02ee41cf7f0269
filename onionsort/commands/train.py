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
import logging
from pathlib import Path

__all__ = ["register"]

logger = logging.getLogger(__name__)


def register(subparsers) -> None:
    """Add the ``train`` subcommand and its models."""
    parser = subparsers.add_parser(
        "train", help="train perception models", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    models = parser.add_subparsers(dest="model", metavar="MODEL", required=True)
    sc = models.add_parser("state-classifier",
                           help="the SA-Net-style classifier: onion/hand location, occluded")
    sc.add_argument("--data", type=Path, required=True, help="dataset folder")
    sc.add_argument("--out", type=Path, required=True, help="run folder for the checkpoint")
    sc.add_argument("--epochs", type=int, default=12)
    sc.add_argument("--batch-size", type=int, default=32)
    sc.add_argument("--seed", type=int, default=0)
    sc.set_defaults(func=run_state_classifier)
    det = models.add_parser("detector", help="the YOLO-style onion detector (good / blemished)")
    det.add_argument("--data", type=Path, required=True, help="dataset folder")
    det.add_argument("--out", type=Path, required=True, help="run folder for the checkpoints")
    det.add_argument("--epochs", type=int, default=24)
    det.add_argument("--images-per-epoch", type=int, default=1600)
    det.add_argument("--batch-size", type=int, default=16)
    det.add_argument("--seed", type=int, default=0)
    det.add_argument("--resume", action="store_true",
                     help="continue the run in --out from its last checkpoint")
    det.set_defaults(func=run_detector)


def run_state_classifier(args: argparse.Namespace) -> int:
    import torch

    from state_abstraction.classifier import ClassifierConfig, train_classifier

    torch.set_num_threads(2)
    if args.epochs < 1:
        raise ValueError(f"--epochs must be >= 1; got {args.epochs}")
    config = ClassifierConfig(epochs=args.epochs, batch_size=args.batch_size, seed=args.seed)
    logger.info("training the state classifier on %s: %s", args.data, config)
    metrics = train_classifier(args.data, args.out, config)
    test = metrics["test"]
    print("state classifier, test split: " + ", ".join(f"{k} {v:.3f}" for k, v in test.items()))
    print(f"wrote {args.out / 'state_classifier.pt'}")
    return 0


def run_detector(args: argparse.Namespace) -> int:
    import torch

    from perception.train import TrainConfig, train_detector

    torch.set_num_threads(2)
    config = TrainConfig(epochs=args.epochs, images_per_epoch=args.images_per_epoch,
                         batch_size=args.batch_size, seed=args.seed)
    logger.info("training the detector on %s: %s", args.data, config)
    metrics = train_detector(args.data, args.out, config, resume=args.resume)
    test = metrics["test"]
    print(f"detector, test split: mAP@0.5 {test['map50']:.3f}, mAP@0.5:0.95 "
          f"{test['map50_95']:.3f}")
    print(f"wrote {args.out / 'detector.pt'}")
    return 0
