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
"""

from __future__ import annotations

import json
import logging
from collections import defaultdict
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np
import torch
from torch import nn

from irl.domains.onion_sorting import Location, Prediction, SortAction

__all__ = ["HEADS", "ClassifierConfig", "StateClassifier", "load_steps", "step_input",
           "train_classifier"]

logger = logging.getLogger(__name__)

DEPTH_SCALE = 5.0
HEADS = {"onion": len(Location), "end_effector": len(Location), "action": len(SortAction),
         "waiting": 2, "occluded": 2}
#: Heads that are read only on unoccluded steps.
FACTOR_HEADS = ("onion", "end_effector", "action", "waiting")


@dataclass(frozen=True)
class ClassifierConfig:
    """Input size and training hyperparameters; ``frames`` is the number of frames per step."""

    width: int = 160
    height: int = 120
    frames: int = 3
    channels: int = 32
    epochs: int = 12
    batch_size: int = 32
    lr: float = 3e-3
    weight_decay: float = 1e-4
    seed: int = 0


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
        z = self.trunk(x)
        return {k: head(z) for k, head in self.heads.items()}

    @torch.no_grad()
    def predict(self, x: torch.Tensor | np.ndarray, batch_size: int = 64
                ) -> dict[str, np.ndarray]:
        """Class probabilities per head, ``{head: [n, n_classes]}``, of steps ``x``."""
        self.eval()
        x = torch.as_tensor(x)
        chunks = [{k: torch.softmax(v, dim=1).numpy()
                   for k, v in self(x[i:i + batch_size].float()).items()}
                  for i in range(0, len(x), batch_size)]
        return {k: np.concatenate([c[k] for c in chunks]) for k in HEADS}

    def save(self, path: Path | str) -> Path:
        path = Path(path)
        tmp = path.with_name(path.name + ".partial")
        torch.save({"config": asdict(self.config), "state_dict": self.state_dict()}, tmp)
        tmp.replace(path)
        return path

    @classmethod
    def load(cls, path: Path | str) -> StateClassifier:
        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(f"no state-classifier checkpoint at {path}")
        ckpt = torch.load(path, map_location="cpu", weights_only=True)
        model = cls(ClassifierConfig(**ckpt["config"]))
        model.load_state_dict(ckpt["state_dict"])
        return model.eval()


def frame_input(color: np.ndarray, depth: np.ndarray, config: ClassifierConfig) -> np.ndarray:
    """One frame as float32 (4, h, w) at the classifier's input size."""
    size = (config.width, config.height)
    rgb = cv2.resize(color, size, interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0
    d = cv2.resize(np.nan_to_num(depth), size, interpolation=cv2.INTER_NEAREST)
    return np.concatenate([rgb.transpose(2, 0, 1), (d / DEPTH_SCALE)[None]], axis=0)


def step_input(colors, depths, config: ClassifierConfig) -> np.ndarray:
    """One step's frames (in time order) as float32 (4 * frames, h, w)."""
    if len(colors) != config.frames or len(depths) != config.frames:
        raise ValueError(f"a step must have {config.frames} frames for this classifier; got "
                         f"{len(colors)} colour and {len(depths)} depth images")
    return np.concatenate([frame_input(c, d, config) for c, d in zip(colors, depths,
                                                                       strict=True)])


def waiting(onion: int, prediction: int) -> int:
    """1 if a claimed onion waits at the gate (on the conveyor, not inspected), else 0."""
    return int(onion == Location.CONVEYOR and prediction == Prediction.UNKNOWN)


def load_steps(root: Path | str, split: str, config: ClassifierConfig):
    """Inputs ``x[n, 4 * frames, h, w]`` (float16) and targets ``{head: [n]}`` of a split.

    Frames are grouped into steps by ``(session, step)``; a step cut short at the end of the
    dataset is left out.
    """
    from recordings.dataset import read_split

    steps: dict[tuple[int, int], list] = defaultdict(list)
    for frame in read_split(root, split):
        rec = frame.record
        key = (rec["session"], rec.get("step", (rec["frame"] - rec["phase"]) // config.frames))
        steps[key].append(frame)
    xs, ys = [], {k: [] for k in HEADS}
    for frames in steps.values():
        frames.sort(key=lambda f: f.record["phase"])
        if len(frames) != config.frames:
            continue
        rec = frames[0].record
        xs.append(step_input([f.color for f in frames], [f.depth for f in frames], config)
                  .astype(np.float16))
        for k in ("onion", "end_effector", "action"):
            ys[k].append(rec[k])
        ys["waiting"].append(waiting(rec["onion"], rec["prediction"]))
        ys["occluded"].append(int(rec["occluded"]))
    if not xs:
        raise ValueError(f"split {split!r} of {root} holds no complete step of "
                         f"{config.frames} frames")
    return torch.from_numpy(np.stack(xs)), {k: torch.tensor(v) for k, v in ys.items()}


def _loss(out: dict, y: dict) -> torch.Tensor:
    ce = nn.functional.cross_entropy
    loss = ce(out["occluded"], y["occluded"])
    visible = y["occluded"] == 0
    if visible.any():
        for k in FACTOR_HEADS:
            loss = loss + ce(out[k][visible], y[k][visible])
    return loss


def evaluate(model: StateClassifier, x: torch.Tensor, y: dict) -> dict:
    """Accuracy per head on unoccluded steps and recall and precision of occluded steps."""
    probs = model.predict(x)
    pred = {k: v.argmax(axis=1) for k, v in probs.items()}
    occ = y["occluded"].numpy() == 1
    metrics = {f"accuracy_{k}": float((pred[k][~occ] == y[k].numpy()[~occ]).mean())
               for k in FACTOR_HEADS if (~occ).any()}
    metrics["occlusion_recall"] = float((pred["occluded"][occ] == 1).mean()) if occ.any() else 1.0
    metrics["occlusion_precision"] = (
        float(occ[pred["occluded"] == 1].mean()) if (pred["occluded"] == 1).any() else 1.0)
    return metrics


def train_classifier(data: Path | str, out: Path | str, config: ClassifierConfig) -> dict:
    """Train on ``data``'s train split, keep the best epoch on val, report test metrics.

    Writes ``out/state_classifier.pt`` and ``out/state_classifier_metrics.json``; returns the
    metrics.
    """
    from tqdm import tqdm

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(config.seed)
    gen = torch.Generator().manual_seed(config.seed)
    x_tr, y_tr = load_steps(data, "train", config)
    x_va, y_va = load_steps(data, "val", config)
    model = StateClassifier(config)
    opt = torch.optim.AdamW(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    steps = config.epochs * ((len(x_tr) + config.batch_size - 1) // config.batch_size)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=config.lr, total_steps=steps)
    best, history = -1.0, []
    for epoch in tqdm(range(config.epochs), desc="state classifier", unit="epoch"):
        model.train()
        order = torch.randperm(len(x_tr), generator=gen)
        total = 0.0
        for i in range(0, len(order), config.batch_size):
            idx = order[i:i + config.batch_size]
            loss = _loss(model(x_tr[idx].float()), {k: v[idx] for k, v in y_tr.items()})
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total += loss.item() * len(idx)
        val = evaluate(model, x_va, y_va)
        score = min(val.values())
        history.append({"epoch": epoch, "train_loss": total / len(x_tr), **val})
        logger.info("epoch %d: %s", epoch, history[-1])
        if score > best:
            best = score
            model.save(out / "state_classifier.pt")
    model = StateClassifier.load(out / "state_classifier.pt")
    x_te, y_te = load_steps(data, "test", config)
    metrics = {"test": evaluate(model, x_te, y_te), "history": history,
               "config": asdict(config)}
    (out / "state_classifier_metrics.json").write_text(json.dumps(metrics, indent=1))
    return metrics
