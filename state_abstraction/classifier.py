"""An SA-Net-style state classifier: one step's frames -> onion, end effector, action, occluded.

Layouts: a step is the stack of its ``frames`` RGB-D frames, as tensors ``x[n, 4 * frames, h,
w]`` with channels (R, G, B, depth) per frame in time order, colour in [0, 1] and depth in metres
divided by ``DEPTH_SCALE``; logits ``[n, n_classes]`` per head.

A recorded step shows the state at rest in its first frame and the action's motion in the
others, so one network reads both from the stack (early fusion): one shared convolutional trunk
whose last feature map is pooled to a coarse grid (where the hand and the onion are matters, so
the pooling keeps their layout), and one head per output:

- ``onion``, ``end_effector``: the state's location factors;
- ``action``: the sorter's action during the step;
- ``waiting``: whether a claimed onion waits at the raised stop gate (the onion is on the
  conveyor, not yet inspected); with the detector's class of the inspected onion this gives the
  prediction factor (see :mod:`state_abstraction.perceive`);
- ``occluded``: the explicit occluded outcome.

The factor losses are masked on occluded steps: there is nothing to read there.

**Depth is optional.** A plain video has no depth. A missing depth image (``None``) enters the
network as a depth channel of zeros, the value a depth camera gives where it has no reading
(NaN pixels are zeroed too). Training zeroes each step's depth channels with probability
``ClassifierConfig.depth_dropout``, so one model reads steps with and without depth.

This package reads no dataset: :func:`train_classifier` takes steps (anything with the
attributes of :class:`LabelledStep`, e.g. ``recordings.labels.dataset.DatasetStep``); reading them
from disk is the ``train`` stage's job (:mod:`onionsort.stages.train`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import cv2
import numpy as np
import torch
from torch import nn

from irl.domains.onion_sorting import SORTING_TASK
from perception.checkpoint import load_checkpoint, save_checkpoint, write_json
from perception.trainer import fit

__all__ = ["HEADS", "OCCLUDED_THRESHOLD", "ClassifierConfig", "LabelledStep", "StateClassifier",
           "drop_depth", "evaluate", "evaluate_steps", "step_input", "step_targets",
           "steps_to_tensors", "train_classifier"]

DEPTH_SCALE = 5.0
#: The task whose factors the camera shows (the prediction factor is read at inspection).
TASK = SORTING_TASK
#: Output heads and their sizes: the camera-visible factors and the action, from the task's
#: description, then whether a claimed onion waits at the gate and whether the view is occluded.
HEADS = {"onion": len(TASK.factors["onion"]), "end_effector": len(TASK.factors["end_effector"]),
         "action": TASK.n_actions, "waiting": 2, "occluded": 2}
#: Heads that are read only on unoccluded steps.
FACTOR_HEADS = ("onion", "end_effector", "action", "waiting")
#: A step is called occluded when ``P(occluded) >= OCCLUDED_THRESHOLD``. Below 0.5 on purpose:
#: a missed occlusion feeds the learner a garbage observation, a false alarm only drops one
#: (MMAP-BIRL marginalizes it). See :mod:`state_abstraction.perceive`.
OCCLUDED_THRESHOLD = 0.2
#: Records written before ``depth_dropout`` existed were trained without it.
_LEGACY_DEPTH_DROPOUT = 0.0


@runtime_checkable
class LabelledStep(Protocol):
    """One labelled step, as the classifier trains on it.

    ``recordings.labels.dataset.DatasetStep`` satisfies it structurally. (``isinstance`` checks only
    that the attributes exist.)

    Attributes
    ----------
    colors : sequence of ndarray, length ``frames``
        (H, W, 3) uint8 RGB, in time order (the first shows the state at rest).
    depths : sequence of (ndarray or None), length ``frames``; or None
        (H, W) float metres; None where there is no depth (then the depth channel is zeros).
    record : mapping
        The labels of the step's first frame: ints ``onion``, ``end_effector``, ``action``,
        ``prediction`` (encodings of :mod:`irl.domains.onion_sorting`) and bool ``occluded``.
    """

    @property
    def colors(self) -> Sequence[np.ndarray]: ...

    @property
    def depths(self) -> Sequence[np.ndarray | None] | None: ...

    @property
    def record(self) -> Mapping[str, Any]: ...


@dataclass(frozen=True)
class ClassifierConfig:
    """Input size and training hyperparameters; ``frames`` is the number of frames per step.

    ``depth_dropout`` is the probability that a training step's depth channels are zeroed (as
    for a step without depth). 0.5 by default: one model serves both modes, so each gets half
    of the examples; the colour-only mode is the harder one (nothing to lean on but colour) and
    the depth mode does not need more than half (depth adds little where colour already shows
    the hand and the onion). Measured on a fresh 500-step dataset (seed 2), the model trained
    so (14 epochs) matched the earlier depth-only model with depth (location factors 1.000,
    action 0.903, occlusion recall 1.000) and kept them without depth, where the earlier model
    fell to 0.64 / 0.48 on the locations. Checkpoints saved before this field existed load
    with 0.0 (they were trained without dropout).
    """

    width: int = 160
    height: int = 120
    frames: int = 3
    channels: int = 32
    epochs: int = 12
    batch_size: int = 32
    lr: float = 3e-3
    weight_decay: float = 1e-4
    seed: int = 0
    depth_dropout: float = 0.5

    def __post_init__(self) -> None:
        for name in ("width", "height", "frames", "channels", "epochs", "batch_size"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1; got {getattr(self, name)}")
        if not 0.0 <= self.depth_dropout <= 1.0:
            raise ValueError(f"depth_dropout must be in [0, 1]; got {self.depth_dropout}")


def _block(c_in: int, c_out: int) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(c_in, c_out, 3, stride=2, padding=1, bias=False),
        nn.BatchNorm2d(c_out), nn.ReLU(inplace=True),
        nn.Conv2d(c_out, c_out, 3, padding=1, bias=False),
        nn.BatchNorm2d(c_out), nn.ReLU(inplace=True),
    )


class StateClassifier(nn.Module):
    """Shared trunk, coarse spatial pooling, one linear head per output."""

    def __init__(self, config: ClassifierConfig = ClassifierConfig()) -> None:
        super().__init__()
        self.config = config
        c = config.channels
        self.trunk = nn.Sequential(_block(4 * config.frames, c), _block(c, 2 * c),
                                   _block(2 * c, 2 * c), _block(2 * c, 4 * c),
                                   nn.AdaptiveAvgPool2d((3, 4)),
                                   nn.Flatten(), nn.Dropout(0.2))
        self.heads = nn.ModuleDict({k: nn.Linear(4 * c * 12, n) for k, n in HEADS.items()})

    def forward(self, x: torch.Tensor) -> dict[str, torch.Tensor]:
        """Logits ``{head: [n, n_classes]}`` of steps ``x[n, 4 * frames, h, w]``."""
        z = self.trunk(x)
        return {k: head(z) for k, head in self.heads.items()}

    @torch.no_grad()
    def predict(self, x: torch.Tensor | np.ndarray, batch_size: int = 64
                ) -> dict[str, np.ndarray]:
        """Class probabilities per head, ``{head: [n, n_classes]}``, of steps ``x``."""
        self.eval()
        x = torch.as_tensor(x)
        device = next(self.parameters()).device
        chunks = [{k: torch.softmax(v.float(), dim=1).cpu().numpy()
                   for k, v in self(x[i:i + batch_size].float().to(device)).items()}
                  for i in range(0, len(x), batch_size)]
        return {k: np.concatenate([c[k] for c in chunks]) for k in HEADS}

    def save(self, path: Path | str) -> Path:
        """Write the configuration and weights to ``path`` (through a temporary name)."""
        return save_checkpoint(path, config=asdict(self.config), state_dict=self)

    @classmethod
    def load(cls, path: Path | str, device: str | torch.device = "cpu") -> StateClassifier:
        """The classifier saved at ``path``, in eval mode, on ``device``."""

        def build(ckpt: dict) -> StateClassifier:
            model = cls(ClassifierConfig(**{"depth_dropout": _LEGACY_DEPTH_DROPOUT,
                                            **ckpt["config"]}))
            model.load_state_dict(ckpt["state_dict"])
            return model

        return load_checkpoint(path, "state-classifier checkpoint", build).to(device).eval()


def frame_input(color: np.ndarray, depth: np.ndarray | None, config: ClassifierConfig
                ) -> np.ndarray:
    """One frame as float32 (4, h, w) at the classifier's input size.

    ``depth`` None gives a depth channel of zeros (as do NaN depth pixels).
    """
    size = (config.width, config.height)
    rgb = cv2.resize(color, size, interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0
    if depth is None:
        d = np.zeros((config.height, config.width), np.float32)
    else:
        d = cv2.resize(np.nan_to_num(np.asarray(depth, np.float32)), size,
                       interpolation=cv2.INTER_NEAREST)
    return np.concatenate([rgb.transpose(2, 0, 1), (d / DEPTH_SCALE)[None]], axis=0)


def step_input(colors: Sequence[np.ndarray], depths: Sequence[np.ndarray | None] | None,
               config: ClassifierConfig) -> np.ndarray:
    """One step's frames (in time order) as float32 ``(4 * frames, h, w)``.

    Parameters
    ----------
    colors : sequence of ndarray, length ``config.frames``
        (H, W, 3) uint8 RGB.
    depths : sequence of (ndarray or None), length ``config.frames``; or None
        (H, W) metres. None (the whole step, or one frame) means no depth: that frame's depth
        channel is zeros, exactly as :func:`drop_depth` makes it in training.
    config : ClassifierConfig
    """
    if depths is None:
        depths = [None] * len(colors)
    if len(colors) != config.frames or len(depths) != config.frames:
        raise ValueError(f"a step must have {config.frames} frames for this classifier; got "
                         f"{len(colors)} colour and {len(depths)} depth images")
    return np.concatenate([frame_input(c, d, config) for c, d in zip(colors, depths,
                                                                       strict=True)])


def depth_channels(frames: int) -> list[int]:
    """Indices of the depth channels in a step's ``4 * frames`` input channels."""
    return [4 * f + 3 for f in range(frames)]


def drop_depth(x: torch.Tensor, p: float, generator: torch.Generator | None = None
               ) -> tuple[torch.Tensor, torch.Tensor]:
    """Zero all depth channels of each step of ``x[n, 4 * frames, h, w]`` with probability ``p``.

    Returns the new batch (``x`` itself is not changed) and the ``[n]`` bool mask of the
    steps whose depth was dropped.
    """
    if not 0.0 <= p <= 1.0:
        raise ValueError(f"p must be in [0, 1]; got {p}")
    if x.ndim != 4 or x.shape[1] % 4:
        raise ValueError(f"x must be [n, 4 * frames, h, w]; got shape {tuple(x.shape)}")
    dropped = torch.rand(len(x), generator=generator) < p
    if not dropped.any():
        return x, dropped
    x = x.clone()
    channels = depth_channels(x.shape[1] // 4)
    x[dropped.nonzero()[:, 0][:, None], torch.tensor(channels)[None]] = 0
    return x, dropped


def augment_colours(x: torch.Tensor, photometric: Callable[[torch.Tensor], torch.Tensor]
                    ) -> torch.Tensor:
    """The steps of ``x[n, 4 * frames, h, w]`` with each step's colour channels passed through
    ``photometric`` (one call per step: its frames, ``[frames, 3, h, w]`` in [0, 1], through
    one camera); depth channels unchanged. ``x`` itself is not changed."""
    n, c, h, w = x.shape
    frames = x.reshape(n, c // 4, 4, h, w).clone()
    for i in range(n):
        frames[i, :, :3] = photometric(frames[i, :, :3])
    return frames.reshape(n, c, h, w)


def waiting(onion: int, prediction: int) -> int:
    """1 if a claimed onion waits at the gate (on the conveyor, not inspected), else 0."""
    return int(onion == TASK.value_index("onion", "conveyor")
               and prediction == TASK.value_index("prediction", "unknown"))


def step_targets(record: Mapping[str, Any]) -> dict[str, int]:
    """The target class of every head, ``{head: int}``, from a step's labels."""
    return {"onion": int(record["onion"]), "end_effector": int(record["end_effector"]),
            "action": int(record["action"]),
            "waiting": waiting(record["onion"], record["prediction"]),
            "occluded": int(bool(record["occluded"]))}


def steps_to_tensors(steps: Sequence[LabelledStep], config: ClassifierConfig, *,
                     with_depth: bool = True) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Inputs ``x[n, 4 * frames, h, w]`` (float16) and targets ``{head: [n]}`` (int64) of steps.

    ``with_depth=False`` ignores the steps' depths (the depth channels are zeros).
    """
    if not steps:
        raise ValueError("steps must hold at least one step; got none")
    xs, ys = [], {k: [] for k in HEADS}
    for step in steps:
        depths = step.depths if with_depth else None
        xs.append(step_input(step.colors, depths, config).astype(np.float16))
        for k, v in step_targets(step.record).items():
            ys[k].append(v)
    return torch.from_numpy(np.stack(xs)), {k: torch.tensor(v) for k, v in ys.items()}


def _loss(out: dict, y: dict) -> torch.Tensor:
    ce = nn.functional.cross_entropy
    loss = ce(out["occluded"], y["occluded"])
    visible = y["occluded"] == 0
    if visible.any():
        for k in FACTOR_HEADS:
            loss = loss + ce(out[k][visible], y[k][visible])
    return loss


def evaluate(model: StateClassifier, x: torch.Tensor, y: dict[str, torch.Tensor], *,
             occluded_threshold: float = OCCLUDED_THRESHOLD) -> dict[str, float]:
    """Accuracy per factor head on truly unoccluded steps; recall and precision of the
    occluded call (``P(occluded) >= occluded_threshold``).

    Parameters
    ----------
    model : StateClassifier
    x : Tensor, [n, 4 * frames, h, w]
    y : dict of str -> Tensor [n]
        Targets per head (:func:`steps_to_tensors`).

    Returns
    -------
    dict
        ``accuracy_<head>`` for the heads of ``FACTOR_HEADS`` (absent if every step is
        occluded), ``occlusion_recall``, ``occlusion_precision`` (1.0 where undefined).
    """
    probs = model.predict(x)
    pred = {k: v.argmax(axis=1) for k, v in probs.items()}
    called = probs["occluded"][:, 1] >= occluded_threshold
    occ = y["occluded"].numpy() == 1
    metrics = {f"accuracy_{k}": float((pred[k][~occ] == y[k].numpy()[~occ]).mean())
               for k in FACTOR_HEADS if (~occ).any()}
    metrics["occlusion_recall"] = float(called[occ].mean()) if occ.any() else 1.0
    metrics["occlusion_precision"] = float(occ[called].mean()) if called.any() else 1.0
    return metrics


def evaluate_steps(model: StateClassifier, steps: Sequence[LabelledStep], *,
                   occluded_threshold: float = OCCLUDED_THRESHOLD) -> dict[str, dict]:
    """:func:`evaluate` on labelled steps, with their depth and with depth removed.

    Returns
    -------
    dict
        ``{"with_depth": metrics, "without_depth": metrics, "n_steps": int,
        "n_occluded": int}``.
    """
    out: dict[str, Any] = {}
    for name, with_depth in (("with_depth", True), ("without_depth", False)):
        x, y = steps_to_tensors(steps, model.config, with_depth=with_depth)
        out[name] = evaluate(model, x, y, occluded_threshold=occluded_threshold)
    out["n_steps"], out["n_occluded"] = len(steps), int(y["occluded"].sum())
    return out


def _val_score(model: StateClassifier, x: torch.Tensor, y: dict, dropout: float
               ) -> tuple[float, dict]:
    """The score that picks the best epoch: the worst metric, in both modes when the model is
    trained for both."""
    val = evaluate(model, x, y)
    if dropout == 0:
        return min(val.values()), val
    no_depth, _ = drop_depth(x, 1.0)
    val_nd = evaluate(model, no_depth, y)
    val.update({f"{k}_without_depth": v for k, v in val_nd.items()})
    return min(val.values()), val


def train_classifier(train: Sequence[LabelledStep], val: Sequence[LabelledStep],
                     test: Sequence[LabelledStep], config: ClassifierConfig,
                     out: Path | str, *, on_epoch: Callable[[dict], None] | None = None,
                     device: str | torch.device = "cpu",
                     photometric: Callable[[torch.Tensor], torch.Tensor] | None = None,
                     init: Path | str | None = None) -> dict:
    """Train on ``train`` (:func:`perception.trainer.fit`), keep the best epoch on ``val``,
    report metrics on ``test``.

    Each training step's depth is zeroed with probability ``config.depth_dropout``. The best
    epoch is the one whose worst validation metric (accuracy of each factor, occlusion recall
    and precision; with and without depth when ``depth_dropout > 0``) is highest.

    Parameters
    ----------
    train, val, test : sequence of LabelledStep
        Steps with ``config.frames`` frames each; ``test`` may be empty (no test metrics).
    config : ClassifierConfig
    out : path
        Folder for ``state_classifier.pt`` and ``state_classifier_metrics.json`` (created).
    on_epoch, device
        As :func:`perception.trainer.fit`'s.
    photometric : callable, optional
        Photometric augmentation of the training steps alone (:func:`augment_colours`; e.g.
        ``perception.photometric.PhotometricAugment()``, which the ``train`` stage passes),
        drawing from torch's generator; never applied to the validation or test steps.
    init : path, optional
        A classifier checkpoint (:meth:`StateClassifier.save`) to start from instead of random
        weights: fine-tuning (its input, ``width``, ``height``, ``frames`` and ``channels``,
        must be ``config``'s).

    Returns
    -------
    dict
        ``test`` (metrics with depth), ``test_without_depth``, ``history`` (one entry per
        epoch), ``config``, ``n_steps`` per split; as written to the metrics file.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(config.seed)
    gen = torch.Generator().manual_seed(config.seed)
    drop_gen = torch.Generator().manual_seed(config.seed + 1)
    x_tr, y_tr = steps_to_tensors(train, config)
    x_va, y_va = steps_to_tensors(val, config)
    device = torch.device(device)
    model = StateClassifier(config)
    if init is not None:
        start = StateClassifier.load(init)
        shape = ("width", "height", "frames", "channels")
        if any(getattr(start.config, k) != getattr(config, k) for k in shape):
            raise ValueError(f"cannot start from {init}: it reads "
                             + ", ".join(f"{k} {getattr(start.config, k)}" for k in shape)
                             + "; this training " + ", ".join(f"{k} {getattr(config, k)}"
                                                               for k in shape))
        model.load_state_dict(start.state_dict())
    model = model.to(device)
    opt = torch.optim.AdamW(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    steps = config.epochs * ((len(x_tr) + config.batch_size - 1) // config.batch_size)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=config.lr, total_steps=steps)

    def batches(epoch: int):
        order = torch.randperm(len(x_tr), generator=gen)
        for i in range(0, len(order), config.batch_size):
            idx = order[i:i + config.batch_size]
            yield x_tr[idx].float(), {k: v[idx].to(device) for k, v in y_tr.items()}, len(idx)

    def augment(x: torch.Tensor) -> torch.Tensor:
        x, _ = drop_depth(x, config.depth_dropout, drop_gen)
        return x if photometric is None else augment_colours(x, photometric)

    history = fit(model, opt, sched, batches, _loss,
                  lambda m: _val_score(m, x_va, y_va, config.depth_dropout), epochs=config.epochs,
                  on_best=lambda m: m.save(out / "state_classifier.pt"), device=device,
                  augment=augment, on_epoch=on_epoch, name="state classifier")
    model = StateClassifier.load(out / "state_classifier.pt", device=device)
    metrics: dict[str, Any] = {}
    if len(test):
        report = evaluate_steps(model, test)
        metrics["test"], metrics["test_without_depth"] = (report["with_depth"],
                                                          report["without_depth"])
    metrics.update({"history": history, "config": asdict(config),
                    "photometric": None if photometric is None else repr(photometric),
                    "n_steps": {"train": len(train), "val": len(val), "test": len(test)}})
    write_json(out / "state_classifier_metrics.json", metrics)
    return metrics
