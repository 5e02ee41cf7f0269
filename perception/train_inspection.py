"""Training the inspection classifier (through :func:`perception.trainer.fit`) on crops of
inspection views.

Training samples are *context crops*: the onion's ground-truth box with more room around it
than the network reads (:data:`CONTEXT_SCALE`), so that each epoch can cut the crop the network
sees with a random shift and scale (:func:`context_crop`, :func:`augment`). Validation samples
are the crops inference cuts (the detector's box, :func:`perception.inspection.crop_onion`): the
epoch kept is the one of lowest weighted validation loss, and its temperature is fitted on them.

Weights: every sample carries one (the ``train`` stage weights difficulty levels and balances
the classes within each); the loss, the choice of epoch and the temperature all use them.
Layouts as in :mod:`perception.inspection`.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from perception.inspection import (
    CROP_MARGIN,
    CROP_SIZE,
    InspectionClassifier,
    InspectionNet,
    InspectionNetConfig,
    crop_onion,
    fit_platt,
    fit_temperature,
    to_tensor,
)
from perception.photometric import PhotometricAugment
from perception.trainer import fit

__all__ = ["CONTEXT_SCALE", "CropSet", "InspectionTrainConfig", "augment", "context_crop",
           "fit_class_map", "train_inspection"]

CONTEXT_SCALE = 1.35
"""A context crop spans this many times the window the network reads."""
CONTEXT_SIZE = round(CROP_SIZE * CONTEXT_SCALE)


@dataclass(frozen=True)
class CropSet:
    """Crops with their labels and weights.

    ``crops`` (N, S, S, 3) uint8; ``labels`` (N,) whether the view shows rot: 1, 0, or -1
    where that is unclear (a sliver of a patch at the rim: left out of the loss and of the
    temperature); ``classes`` (N,) the onion's class (1 blemished); ``weights`` (N,) > 0.
    """

    crops: np.ndarray
    labels: np.ndarray
    classes: np.ndarray
    weights: np.ndarray

    def __post_init__(self) -> None:
        n = len(self.crops)
        if not n:
            raise ValueError("a crop set needs at least one crop; got none")
        if not len(self.labels) == len(self.classes) == len(self.weights) == n:
            raise ValueError(f"crops, labels, classes and weights must be of one length; got "
                             f"{n}, {len(self.labels)}, {len(self.classes)} and "
                             f"{len(self.weights)}")
        if not np.all(np.asarray(self.weights) > 0):
            raise ValueError("weights must be > 0")
        if not np.isin(self.labels, (-1, 0, 1)).all() or not np.isin(self.classes, (0, 1)).all():
            raise ValueError("labels must be -1, 0 or 1 and classes 0 or 1")


@dataclass(frozen=True)
class InspectionTrainConfig:
    """Training hyperparameters (the network's are in
    :class:`~perception.inspection.InspectionNetConfig`).

    Augmentation (:func:`augment`): the crop window moves by up to ``shift`` of its side and
    scales within ``scale``; the brightness varies by up to ``brightness``, each channel by up
    to ``color`` more; Gaussian noise of a standard deviation up to ``noise`` grey levels is
    added; and a share ``jpeg`` of the crops is re-encoded as JPEG of quality 30-90. The views
    of every difficulty level are in the training set; these spread them further. With
    ``photometric``, each crop is then seen through a camera of its own as well
    (:class:`perception.photometric.PhotometricAugment`: white balance, exposure, tone curve,
    defocus, noise, JPEG); never at validation or inference.
    """

    epochs: int = 30
    batch_size: int = 128
    lr: float = 3e-3
    weight_decay: float = 5e-4
    shift: float = 0.08
    scale: tuple[float, float] = (0.85, 1.15)
    brightness: float = 0.12
    color: float = 0.06
    noise: float = 6.0
    jpeg: float = 0.3
    seed: int = 0
    photometric: bool = True

    def __post_init__(self) -> None:
        if self.epochs < 1:
            raise ValueError(f"epochs must be >= 1; got {self.epochs}")
        if self.batch_size < 2:
            raise ValueError(f"batch_size must be >= 2; got {self.batch_size}")
        if not self.lr > 0:
            raise ValueError(f"lr must be > 0; got {self.lr}")


def context_crop(rgb: np.ndarray, box) -> np.ndarray:
    """The context crop (:data:`CONTEXT_SIZE` square, uint8) of the onion in ``box``."""
    return crop_onion(rgb, box, CONTEXT_SIZE, scale=CONTEXT_SCALE)


def augment(context: np.ndarray, rng: np.random.Generator, config: InspectionTrainConfig
            ) -> np.ndarray:
    """A training crop (:data:`~perception.inspection.CROP_SIZE` square) cut from a context
    crop: shifted and scaled at random, mirrored half the time, its brightness and colour
    jittered, noise added and, at times, JPEG artefacts (see :class:`InspectionTrainConfig`)."""
    c = CONTEXT_SIZE / 2
    half = CONTEXT_SIZE / CONTEXT_SCALE / (1 + 2 * CROP_MARGIN) / 2  # the box, in the context
    crop = crop_onion(context, (c - half, c - half, c + half, c + half), CROP_SIZE,
                      shift=tuple(rng.uniform(-config.shift, config.shift, 2)),
                      scale=float(rng.uniform(*config.scale)))
    if rng.random() < 0.5:
        crop = crop[:, ::-1]
    img = crop.astype(np.float32)
    gain = (1.0 + rng.uniform(-config.brightness, config.brightness)) * (
        1.0 + rng.uniform(-config.color, config.color, 3))
    img = img * gain.astype(np.float32)
    if config.noise:
        img = img + rng.normal(0.0, rng.uniform(0.0, config.noise), img.shape)
    crop = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    if config.jpeg and rng.random() < config.jpeg:
        import cv2

        ok, buf = cv2.imencode(".jpg", np.ascontiguousarray(crop),
                               [cv2.IMWRITE_JPEG_QUALITY, int(rng.integers(30, 91))])
        if ok:
            crop = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED)
    return np.ascontiguousarray(crop)


def _weighted_loss(logits: torch.Tensor, labels: torch.Tensor, weights: torch.Tensor
                   ) -> torch.Tensor:
    per = nn.functional.binary_cross_entropy_with_logits(logits, labels, reduction="none")
    return (per * weights).sum() / weights.sum()


def _nll(logits: np.ndarray, labels: np.ndarray, weights: np.ndarray) -> float:
    per = np.logaddexp(0.0, logits) - labels * logits
    return float(np.sum(per * weights) / np.sum(weights))


def _accuracy(logits: np.ndarray, labels: np.ndarray, weights: np.ndarray) -> float:
    return float(np.sum(weights * ((logits > 0) == (labels > 0.5))) / weights.sum())


def _class_weights(classes: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """``weights`` rescaled so that both classes weigh the same in all."""
    out = np.asarray(weights, float).copy()
    for c in (0, 1):
        mine = classes == c
        if mine.any():
            out[mine] *= 0.5 / out[mine].sum()
    return out


def fit_class_map(logits: np.ndarray, classes: np.ndarray, weights: np.ndarray
                  ) -> tuple[float, float]:
    """Platt's map ``(a, b)`` from a view's logit to P(its onion is blemished)
    (:func:`perception.inspection.fit_platt`) on views of onions of ``classes`` (N,), each
    view weighing its ``weights`` (N,), both classes weighing the same in all."""
    classes = np.asarray(classes, float)
    return fit_platt(logits, classes, _class_weights(classes, np.asarray(weights, float)))


def train_inspection(train: CropSet, val: CropSet, config: InspectionTrainConfig,
                     net_config: InspectionNetConfig | None = None, *,
                     rule: str = "noisy-or", device: str | torch.device = "cpu",
                     on_epoch: Callable[[dict], None] | None = None,
                     init: Path | str | None = None) -> tuple[InspectionClassifier, dict]:
    """Train the network to see rot on ``train`` context crops; keep the epoch of lowest
    weighted validation loss on ``val`` (inference crops); fit its calibrations there.

    Crops whose label is unclear (-1) are left out of the loss, the choice of epoch and the
    temperature; Platt's scaling to the onion's class uses every validation crop, its classes
    weighted equally (so ``train_prior`` is 0.5). ``on_epoch`` and ``device`` are
    :func:`perception.trainer.fit`'s. ``init`` is an inspection classifier
    (:meth:`InspectionClassifier.save`) whose network to start from instead of random weights
    (fine-tuning; its network must be ``net_config``).

    Returns
    -------
    classifier : InspectionClassifier
        Calibrated, with fusion rule ``rule``.
    metrics : dict
        ``history`` (per epoch: train loss, validation loss and accuracy), ``best_epoch``,
        ``temperature``, ``platt``, ``val`` (loss and accuracy of the kept epoch, before and
        after the temperature).
    """
    net_config = InspectionNetConfig() if net_config is None else net_config
    device = torch.device(device)
    torch.manual_seed(config.seed)
    rng = np.random.default_rng(config.seed)
    known = np.asarray(train.labels) >= 0
    if not known.any():
        raise ValueError("train holds no crop with a clear label")
    crops = np.asarray(train.crops)[known]
    labels = np.asarray(train.labels, np.float32)[known]
    weights = np.asarray(train.weights, np.float32)[known]
    val_known = np.asarray(val.labels) >= 0
    if not val_known.any():
        raise ValueError("val holds no crop with a clear label")
    val_y = np.asarray(val.labels, float)[val_known]
    val_w = np.asarray(val.weights, float)[val_known]
    net = InspectionNet(net_config)
    if init is not None:
        start = InspectionClassifier.load(init).net
        if start.config != net_config:
            raise ValueError(f"cannot start from {init}: its network is {start.config}, not "
                             f"{net_config}")
        net.load_state_dict(start.state_dict())
    net = net.to(device)
    steps_per_epoch = max(1, math.ceil(len(crops) / config.batch_size))
    opt = torch.optim.AdamW(net.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=config.lr, epochs=config.epochs,
                                                steps_per_epoch=steps_per_epoch,
                                                pct_start=0.15)

    def batches(epoch: int):
        order = rng.permutation(len(crops))
        for i in range(0, len(order), config.batch_size):
            idx = order[i:i + config.batch_size]
            if len(idx) < 2:
                continue  # batch norm needs two samples
            w = torch.from_numpy(weights[idx]).to(device)
            yield (to_tensor([augment(crops[j], rng, config) for j in idx]),
                   (torch.from_numpy(labels[idx]).to(device), w), float(w.sum()))

    def validate(model: InspectionNet) -> tuple[float, dict]:
        z = InspectionClassifier(model, device=device).logits(np.asarray(val.crops)[val_known])
        val_loss = _nll(z, val_y, val_w)
        return -val_loss, {"val_loss": val_loss, "val_accuracy": _accuracy(z, val_y, val_w)}

    best = {}
    history = fit(net, opt, sched, batches, lambda logits, yw: _weighted_loss(logits, *yw),
                  validate, epochs=config.epochs, device=device,
                  augment=PhotometricAugment().each if config.photometric else None,
                  on_best=lambda model: best.update(copy.deepcopy(model.state_dict())),
                  on_epoch=on_epoch, name="inspection classifier")
    best_epoch = min(history, key=lambda h: h["val_loss"])["epoch"]  # the first of the least
    net.load_state_dict(best)
    z_all = InspectionClassifier(net, device=device).logits(np.asarray(val.crops))
    z = z_all[val_known]
    temperature = fit_temperature(z, val_y, val_w)
    platt = fit_class_map(z_all, val.classes, val.weights)
    metrics = {
        "history": history, "best_epoch": best_epoch, "temperature": temperature,
        "platt": list(platt), "config": {**asdict(config), "scale": list(config.scale)},
        "net": asdict(net_config),
        "val": {"loss": _nll(z, val_y, val_w),
                "loss_calibrated": _nll(z / temperature, val_y, val_w),
                "accuracy": _accuracy(z, val_y, val_w),
                "n": int(val_known.sum()), "n_unclear": int((~val_known).sum())},
        "n_train": int(known.sum()), "n_train_unclear": int((~known).sum()),
    }
    # the share of rot views the probabilities are calibrated to, smoothed (one view of each
    # kind more) so that a small split showing only one kind still gives a prior in (0, 1)
    rot_prior = float((np.sum(val_w * val_y) + 1.0) / (np.sum(val_w) + 2.0))
    blemished = np.asarray(train.classes)[known] == 1
    visibility = (float(np.sum(weights[blemished] * labels[blemished])
                        / np.sum(weights[blemished])) if blemished.any() else 1.0)
    visibility = min(max(visibility, 0.05), 1.0)
    metrics.update({"rot_prior": rot_prior, "visibility": visibility})
    classifier = InspectionClassifier(net.cpu(), temperature, platt, 0.5, rot_prior=rot_prior,
                                      visibility=visibility, rule=rule,
                                      metadata={"best_epoch": best_epoch, "val": metrics["val"]},
                                      device=device)
    return classifier, metrics
