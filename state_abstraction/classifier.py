"""An SA-Net-style state classifier: RGB-D frame -> onion location, end-effector location, occluded.

Layouts: frames as tensors ``x[n, c, h, w]`` with channels (R, G, B, depth), colour in [0, 1]
and depth in metres divided by ``DEPTH_SCALE``; logits ``[n, n_classes]`` per head.

One shared convolutional trunk, whose last feature map is pooled to a coarse grid (where the
hand and the onion are matters, so the pooling keeps their layout), and one head per state
factor plus an explicit occluded outcome. The factor losses are masked on occluded frames:
there is nothing to read there. The prediction factor (good / bad / unknown) is not read off the
scene; it comes from the detector's class of the inspected onion.
"""

from __future__ import annotations

import json
import logging
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np
import torch
from torch import nn

from irl.domains.onion_sorting import Location

__all__ = ["ClassifierConfig", "StateClassifier", "load_frames", "train_classifier"]

logger = logging.getLogger(__name__)

DEPTH_SCALE = 5.0
HEADS = {"onion": len(Location), "end_effector": len(Location), "occluded": 2}


@dataclass(frozen=True)
class ClassifierConfig:
    """Input size and training hyperparameters."""

    width: int = 160
    height: int = 120
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
        self.trunk = nn.Sequential(_block(4, c), _block(c, 2 * c), _block(2 * c, 2 * c),
                                   _block(2 * c, 4 * c), nn.AdaptiveAvgPool2d((3, 4)),
                                   nn.Flatten(), nn.Dropout(0.2))
        self.heads = nn.ModuleDict({k: nn.Linear(4 * c * 12, n) for k, n in HEADS.items()})

    def forward(self, x: torch.Tensor) -> dict[str, torch.Tensor]:
        z = self.trunk(x)
        return {k: head(z) for k, head in self.heads.items()}

    @torch.no_grad()
    def predict(self, x: torch.Tensor) -> dict[str, np.ndarray]:
        """Class probabilities per head, ``{head: [n, n_classes]}``."""
        self.eval()
        return {k: torch.softmax(v, dim=1).numpy() for k, v in self(x).items()}

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


def to_input(color: np.ndarray, depth: np.ndarray, config: ClassifierConfig) -> np.ndarray:
    """One frame as a float32 array (4, h, w) at the classifier's input size."""
    size = (config.width, config.height)
    rgb = cv2.resize(color, size, interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0
    d = cv2.resize(np.nan_to_num(depth), size, interpolation=cv2.INTER_NEAREST)
    return np.concatenate([rgb.transpose(2, 0, 1), (d / DEPTH_SCALE)[None]], axis=0)


def load_frames(root: Path | str, split: str, config: ClassifierConfig):
    """Inputs ``x[n, 4, h, w]`` and targets ``{head: [n]}`` of a dataset split."""
    from recordings.dataset import read_split

    xs, ys = [], {k: [] for k in HEADS}
    for frame in read_split(root, split):
        xs.append(to_input(frame.color, frame.depth, config))
        for k in ("onion", "end_effector"):
            ys[k].append(frame.record[k])
        ys["occluded"].append(int(frame.record["occluded"]))
    if not xs:
        raise ValueError(f"split {split!r} of {root} holds no frames")
    return torch.from_numpy(np.stack(xs)), {k: torch.tensor(v) for k, v in ys.items()}


def _loss(out: dict, y: dict) -> torch.Tensor:
    ce = nn.functional.cross_entropy
    loss = ce(out["occluded"], y["occluded"])
    visible = y["occluded"] == 0
    if visible.any():
        for k in ("onion", "end_effector"):
            loss = loss + ce(out[k][visible], y[k][visible])
    return loss


def evaluate(model: StateClassifier, x: torch.Tensor, y: dict) -> dict:
    """Accuracy per factor on unoccluded frames and recall of occluded frames."""
    probs = model.predict(x)
    pred = {k: v.argmax(axis=1) for k, v in probs.items()}
    occ = y["occluded"].numpy() == 1
    metrics = {f"accuracy_{k}": float((pred[k][~occ] == y[k].numpy()[~occ]).mean())
               for k in ("onion", "end_effector") if (~occ).any()}
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
    x_tr, y_tr = load_frames(data, "train", config)
    x_va, y_va = load_frames(data, "val", config)
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
            loss = _loss(model(x_tr[idx]), {k: v[idx] for k, v in y_tr.items()})
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
    x_te, y_te = load_frames(data, "test", config)
    metrics = {"test": evaluate(model, x_te, y_te), "history": history,
               "config": asdict(config)}
    (out / "state_classifier_metrics.json").write_text(json.dumps(metrics, indent=1))
    return metrics
