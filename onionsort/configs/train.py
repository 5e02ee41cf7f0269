"""The configs of stage ``train`` (:mod:`onionsort.stages.train`), and the options every
training command shares (its datasets, its run folder, augmentation, a checkpoint to start
from)."""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

from onionsort.configs import common, documented, option
from onionsort.configs.calibrate import camera_seeds, check_camera_seeds

__all__ = ["ClassifierTrainConfig", "DetectorTrainConfig", "TrainOptions", "augment",
           "check_through_cameras", "data", "data_weights", "init", "through_cameras",
           "weights"]


#: The help of ``--epochs`` and ``--batch-size``, whose defaults differ by model
EPOCHS = "passes over the training data; the epoch of best validation score is kept"
BATCH_SIZE = "training samples per optimizer step"


def weights(text: str) -> tuple[int, ...]:
    """Positive integers joined by commas, for argparse ``type=``."""
    try:
        parsed = tuple(int(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected positive integers joined by commas, e.g. 3,1; got {text!r}") from None
    if not parsed or min(parsed) < 1:
        raise argparse.ArgumentTypeError(
            f"expected positive integers joined by commas, e.g. 3,1; got {text!r}")
    return parsed


def data(help: str = "dataset folder (repeat it to pool several, e.g. a lab's frames from "
                     "`onionsort label import` and rendered ones)"):
    """``--data``, repeated: the dataset folders a model trains on, pooled."""
    return option(type=Path, action="append", help=help)


def data_weights():
    """``--data-weights W,W,...``: how many times each ``--data``'s training frames count."""
    return option((), type=weights, metavar="W,W,...",
                  help="how many times each --data's training frames count, in their order, "
                       "e.g. 3,1 (default: 1 each)")


def augment():
    """``--augment`` / ``--no-augment``: photometric augmentation at training (on)."""
    return option(True, action=argparse.BooleanOptionalAction,
                  help="see each training sample through a camera of its own (white balance, "
                       "exposure, tone curve, defocus, noise, JPEG), never at evaluation")


def init(what: str):
    """``--init CHECKPOINT``: ``what`` to fine-tune instead of training from scratch."""
    return option(None, metavar="CHECKPOINT",
                  help=f"{what} to fine-tune instead of training from scratch (default: none)")


def through_cameras(what: str):
    """``--through-cameras SEEDS``: each training ``what`` also seen through the camera its
    session (or line-up) has under ``eval-perception --camera-shift SEED``."""
    return option((), metavar="SEEDS", type=camera_seeds,
                  help=f"also train on each {what} seen through the camera its session has "
                       "under `eval-perception --camera-shift SEED`, once per seed of SEEDS "
                       "(ints >= 0, comma-separated; seeds your evaluation does not use), and "
                       "validate through the first too (default: none)")


def check_through_cameras(config) -> None:
    """Check ``config.through_cameras`` (none, or seeds as
    :func:`~onionsort.configs.calibrate.check_camera_seeds` takes them) and store it as a
    tuple."""
    if config.through_cameras != ():
        object.__setattr__(config, "through_cameras",
                           check_camera_seeds(config.through_cameras, "through_cameras"))


@documented
@dataclass(frozen=True, kw_only=True)
class TrainOptions:
    """What training any model takes: its datasets (their splits pooled), its run folder and
    hyperparameters (each model's config gives the defaults of ``epochs`` and
    ``batch_size``); ``augment`` is :class:`perception.photometric.PhotometricAugment`."""

    data: Path | tuple[Path, ...] = data()
    data_weights: tuple[int, ...] = data_weights()
    out: Path = option(help="run folder for the checkpoints")
    epochs: int = option(help=EPOCHS)
    batch_size: int = option(help=BATCH_SIZE)
    seed: int = common.seed("seed of the initial weights, the batches and the augmentation")
    augment: bool = augment()
    device: str = common.device()

    def __post_init__(self) -> None:
        data = (self.data,) if isinstance(self.data, str | Path) else tuple(self.data)
        if not data:
            raise ValueError("data must name at least one dataset folder; got none")
        weights = tuple(self.data_weights) or (1,) * len(data)
        if len(weights) != len(data):
            raise ValueError(f"data_weights must give one weight per dataset ({len(data)}); "
                             f"got {len(weights)}: {','.join(map(str, weights))}")
        for w in weights:
            if isinstance(w, bool) or not float(w).is_integer() or w < 1:
                raise ValueError("data_weights must be positive integers (how many times each "
                                 f"dataset's training frames count); got {w}")
        object.__setattr__(self, "data", tuple(Path(d) for d in data))
        object.__setattr__(self, "data_weights", tuple(int(w) for w in weights))
        object.__setattr__(self, "out", Path(self.out))
        common.check_device(self.device)
        _check_positive(self, "epochs", "batch_size")


def lr(default: float):
    """``--lr``: the peak learning rate (a smaller one suits fine-tuning from ``--init``)."""
    return option(default, help="peak learning rate (a smaller one suits fine-tuning from "
                                "--init)")


def check_lr(value: float) -> None:
    """Refuse a learning rate that is not > 0."""
    if not value > 0:
        raise ValueError(f"lr must be > 0; got {value}")


def _check_positive(config, *names: str) -> None:
    for name in names:
        if getattr(config, name) < 1:
            raise ValueError(f"{name} must be >= 1; got {getattr(config, name)}")


@documented
@dataclass(frozen=True, kw_only=True)
class ClassifierTrainConfig(TrainOptions):
    """``onionsort train state-classifier``: dataset folders, run folder, hyperparameters
    (``depth_dropout``: :class:`state_abstraction.classifier.ClassifierConfig`'s); a smaller
    ``lr`` suits fine-tuning from ``init``."""

    epochs: int = option(12, help=EPOCHS)
    batch_size: int = option(32, help=BATCH_SIZE)
    depth_dropout: float = option(0.5, help="probability that a training step's depth is "
                                            "zeroed, so the model also reads steps without "
                                            "depth")
    init: Path | None = init("a state_classifier.pt")
    lr: float = lr(3e-3)

    def __post_init__(self) -> None:
        super().__post_init__()
        check_lr(self.lr)
        if not 0.0 <= self.depth_dropout <= 1.0:
            raise ValueError(f"depth_dropout must be in [0, 1]; got {self.depth_dropout}")


@documented
@dataclass(frozen=True, kw_only=True)
class DetectorTrainConfig(TrainOptions):
    """``onionsort train detector``: dataset folders, run folder, hyperparameters; a smaller
    ``lr`` suits fine-tuning from ``init``. With ``through_cameras`` each training camera
    frame is also seen through the camera its session has under ``eval-perception
    --camera-shift SEED``, once per seed, at the frame's own resolution (and each validation
    frame through the first seed's)."""

    epochs: int = option(24, help=EPOCHS)
    batch_size: int = option(16, help=BATCH_SIZE)
    images_per_epoch: int = option(1600, help="training images drawn per epoch (weighted by "
                                              "--data-weights)")
    init: Path | None = init("a detector.pt")
    lr: float = lr(2e-3)
    resume: bool = option(False, help="continue the run in --out from its last checkpoint")
    through_cameras: tuple[int, ...] = through_cameras("camera frame")

    def __post_init__(self) -> None:
        super().__post_init__()
        _check_positive(self, "images_per_epoch")
        check_through_cameras(self)
