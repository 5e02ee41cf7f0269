"""``onionsort train``: train perception models on a dataset from ``onionsort dataset``.

Examples
--------
    onionsort dataset --frames 3000 --out runs/data
    onionsort train state-classifier --data runs/data --out runs/perception
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
