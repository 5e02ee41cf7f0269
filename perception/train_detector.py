"""Training (through :func:`perception.trainer.fit`) and evaluation of the detector on
labelled images.

Checkpoints: ``OUT/detector_last.pt`` after every epoch (network, EMA, optimiser, scheduler,
epoch, configuration: what ``resume`` continues from), ``OUT/detector.pt`` the EMA weights of the
best epoch by validation mAP@0.5:0.95, and ``OUT/detector_metrics.json``.

The images come as ``(image, boxes, classes)`` triples (:data:`perception.data.LabelledImage`);
the ``train`` stage (:mod:`onionsort.stages.train`) reads them from a dataset.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from perception.assign import detection_loss
from perception.checkpoint import load_checkpoint, write_json
from perception.data import LabelledImage, Sample, augment, to_samples
from perception.detector import Detector, postprocess
from perception.metrics import mean_average_precision
from perception.model import DetectorConfig, DetectorNet, grid_points
from perception.photometric import PhotometricAugment
from perception.trainer import ema, fit

__all__ = ["TrainConfig", "evaluate_detector", "train_detector"]

#: Score threshold when measuring mAP (low, as is usual: mAP integrates over scores).
EVAL_SCORE_THRESHOLD = 0.01


@dataclass(frozen=True)
class TrainConfig:
    """Training hyperparameters (the network's own are in :class:`DetectorConfig`).

    An epoch is ``images_per_epoch`` images drawn afresh from the train split (consecutive
    frames of a session are near duplicates, so full passes waste time on a CPU).
    ``photometric``: each training image is also seen through a camera of its own
    (:class:`perception.photometric.PhotometricAugment`); never at evaluation.
    """

    epochs: int = 24
    images_per_epoch: int = 1600
    batch_size: int = 16
    lr: float = 2e-3
    weight_decay: float = 5e-4
    warmup_epochs: float = 1.0
    ema_decay: float = 0.998
    seed: int = 0
    photometric: bool = True

    def __post_init__(self) -> None:
        if self.epochs < 1:
            raise ValueError(f"epochs must be >= 1; got {self.epochs}")
        if self.images_per_epoch < 1:
            raise ValueError(f"images_per_epoch must be >= 1; got {self.images_per_epoch}")
        if self.batch_size < 1:
            raise ValueError(f"batch_size must be >= 1; got {self.batch_size}")


def _batch(samples: list[Sample], device: torch.device | None = None):
    x = torch.from_numpy(np.stack([s.image for s in samples])).permute(0, 3, 1, 2).float()
    targets = [(torch.from_numpy(s.boxes).float().to(device),
                torch.from_numpy(s.classes).long().to(device)) for s in samples]
    return (x / 255.0).to(device), targets


@torch.no_grad()
def evaluate_detector(net: DetectorNet, samples: list[Sample], batch_size: int = 32
                      ) -> dict[str, float]:
    """mAP of ``net`` on canvas samples."""
    net.eval()
    device = next(net.parameters()).device
    points, _ = grid_points(net.config.height, net.config.width)
    points = points.to(device)
    gts, dts = [], []
    for i in range(0, len(samples), batch_size):
        chunk = samples[i:i + batch_size]
        x, _ = _batch(chunk, device)
        logits, ltrb = net(x)
        for s, (b, sc, c) in zip(chunk, postprocess(logits, ltrb, points, net.config,
                                                    EVAL_SCORE_THRESHOLD), strict=True):
            gts.append((s.boxes, s.classes))
            dts.append((b.cpu().numpy(), sc.cpu().numpy(), c.cpu().numpy()))
    return mean_average_precision(gts, dts)


def _schedule(step: int, total: int, warmup: int) -> float:
    if step < warmup:
        return (step + 1) / warmup
    return 0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * (step - warmup) / max(1, total - warmup)))


def train_detector(train: Sequence[LabelledImage], val: Sequence[LabelledImage],
                   test: Sequence[LabelledImage], config: TrainConfig, out: Path | str,
                   net_config: DetectorConfig | None = None, *, resume: bool = False,
                   on_epoch: Callable[[dict], None] | None = None,
                   device: str | torch.device = "cpu", init: Path | str | None = None) -> dict:
    """Train on ``train``; keep the best epoch on ``val``; report val and test mAP.

    Parameters
    ----------
    train, val, test : sequence of (image, boxes, classes)
        Labelled images (:data:`perception.data.LabelledImage`); ``train`` may repeat an image
        to oversample it. ``test`` may be empty (no test mAP).
    config : TrainConfig
    out : path
        Run folder for the checkpoints and ``detector_metrics.json`` (created).
    net_config : DetectorConfig, optional
        The network (default :class:`DetectorConfig`).
    resume : bool
        Continue the run in ``out`` from ``detector_last.pt``, exactly (same images, same
        configuration).
    on_epoch, device
        As :func:`perception.trainer.fit`'s (``epoch`` counts from 0, from the resumed epoch
        on ``resume``).
    init : path, optional
        A detector checkpoint (:meth:`perception.Detector.save`) to start from instead of
        random weights: fine-tuning (its configuration must be ``net_config``).

    Returns
    -------
    dict
        The metrics written to ``out/detector_metrics.json``.
    """
    net_config = DetectorConfig() if net_config is None else net_config
    out = Path(out)
    last = out / "detector_last.pt"
    if resume and not last.is_file():
        raise FileNotFoundError(f"cannot resume: {last} does not exist")
    for name, images in (("train", train), ("val", val)):
        if not len(images):
            raise ValueError(f"{name} must hold at least one labelled image; got none")
    out.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(config.seed)
    rng = np.random.default_rng(config.seed)
    train_samples = to_samples(train, net_config.width, net_config.height)
    val_samples = to_samples(val, net_config.width, net_config.height)
    device = torch.device(device)
    net = DetectorNet(net_config)
    if init is not None:
        start_from = Detector.load(init).net
        if start_from.config != net_config:
            raise ValueError(f"cannot start from {init}: its network is {start_from.config}, "
                             f"not {net_config}")
        net.load_state_dict(start_from.state_dict())
    net = net.to(device)
    average = ema(net, config.ema_decay)
    opt = torch.optim.AdamW(net.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    n_epoch = min(config.images_per_epoch, len(train_samples))
    per_epoch = math.ceil(n_epoch / config.batch_size)
    total, warmup = config.epochs * per_epoch, int(config.warmup_epochs * per_epoch)
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda k: _schedule(k, total, warmup))
    ckpt = load_checkpoint(last, "detector training checkpoint") if resume else None
    if ckpt is not None:
        # a run saved before the field existed trained without photometric augmentation
        saved = {"photometric": False, **ckpt["train_config"]}
        if saved != asdict(config) or ckpt["config"] != net_config.to_dict():
            raise ValueError(f"cannot resume from {last}: it was trained with "
                             f"{ckpt['train_config']}, {ckpt['config']}")
    points, strides = grid_points(net_config.height, net_config.width)
    points, strides = points.to(device), strides.to(device)

    def batches(epoch: int):
        order = rng.permutation(len(train_samples))[:n_epoch]
        for i in range(0, len(order), config.batch_size):
            x, targets = _batch([augment(train_samples[j], rng)
                                 for j in order[i:i + config.batch_size]], device)
            yield x, targets, 1.0

    def validate(model: DetectorNet) -> tuple[float, dict]:
        metrics = evaluate_detector(model, val_samples)
        return metrics["map50_95"], {f"val_{k}": v for k, v in metrics.items()}

    history = fit(net, opt, sched, batches,
                  lambda outputs, targets: detection_loss(*outputs, points, strides, targets)[0],
                  validate, epochs=config.epochs, device=device, clip_grad=10.0,
                  augment=PhotometricAugment().each if config.photometric else None,
                  average=average, on_best=lambda m: Detector(m, device).save(out / "detector.pt"),
                  on_epoch=on_epoch, last=last, rng=rng, resume=ckpt, name="detector",
                  meta={"config": net_config.to_dict(), "train_config": asdict(config)})
    best_net = Detector.load(out / "detector.pt", device=device).net
    test_samples = to_samples(test, net_config.width, net_config.height)
    result = {"val": evaluate_detector(best_net, val_samples),
              "test": evaluate_detector(best_net, test_samples) if test_samples else None,
              "history": history, "config": net_config.to_dict(), "train": asdict(config),
              "n_train_images": len(train_samples), "n_test_images": len(test_samples)}
    write_json(out / "detector_metrics.json", result)
    return result
