"""Inference with the trained detector: images in, class-aware NMS-filtered boxes out.

Layouts: images (H, W, 3) uint8 RGB of any size (letterboxed onto the network's canvas);
:class:`Detections` hold ``boxes[D, 4]`` (x_min, y_min, x_max, y_max, pixels of the input image),
``scores[D]`` and ``classes[D]`` (0 good, 1 blemished).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torchvision.ops import batched_nms

from perception.assign import decode
from perception.checkpoint import load_checkpoint, save_checkpoint
from perception.data import letterbox
from perception.model import DetectorConfig, DetectorNet, grid_points

__all__ = ["Detections", "Detector", "postprocess"]


@dataclass(frozen=True)
class Detections:
    """The detections of one image (see the module docstring)."""

    boxes: np.ndarray
    scores: np.ndarray
    classes: np.ndarray

    def __len__(self) -> int:
        return len(self.scores)


def postprocess(logits: torch.Tensor, ltrb: torch.Tensor, points: torch.Tensor,
                config: DetectorConfig, score_threshold: float | None = None
                ) -> list[tuple[torch.Tensor, torch.Tensor, torch.Tensor]]:
    """Per image (boxes [D, 4], scores [D], classes [D]) on the canvas, after class-aware NMS.

    Every (point, class) pair whose score passes the threshold is a candidate, as in YOLOv8.
    """
    thr = config.score_threshold if score_threshold is None else score_threshold
    scores = logits.sigmoid()
    boxes = decode(points, ltrb)
    out = []
    for i in range(len(scores)):
        p, c = torch.nonzero(scores[i] >= thr, as_tuple=True)
        s, b = scores[i, p, c], boxes[i, p]
        keep = batched_nms(b, s, c, config.iou_threshold)[:config.max_detections]
        out.append((b[keep], s[keep], c[keep]))
    return out


class Detector:
    """The trained network with its configuration; call :meth:`detect` on images."""

    def __init__(self, net: DetectorNet, device: str | torch.device = "cpu") -> None:
        self.device = torch.device(device)
        self.net = net.to(self.device).eval()
        self.config = net.config
        self.points, _ = grid_points(self.config.height, self.config.width)
        self.points = self.points.to(self.device)

    @classmethod
    def load(cls, path: Path | str, device: str | torch.device = "cpu") -> Detector:
        """Load weights saved by :meth:`save` (or the ``model`` of a training checkpoint) onto
        ``device``."""

        def build(ckpt: dict) -> DetectorNet:
            net = DetectorNet(DetectorConfig(**ckpt["config"]))
            net.load_state_dict(ckpt["model"])
            return net

        return cls(load_checkpoint(path, "detector checkpoint", build), device)

    def save(self, path: Path | str) -> Path:
        """Write the weights and configuration (atomically)."""
        return save_checkpoint(path, config=self.config.to_dict(), model=self.net)

    @torch.no_grad()
    def detect(self, images: list[np.ndarray], score_threshold: float | None = None
               ) -> list[Detections]:
        """Detect onions in RGB images (H, W, 3) uint8; boxes in each image's pixels."""
        if not images:
            return []
        canvases, boxes = [], []
        for img in images:
            img = np.asarray(img)
            if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
                raise ValueError(f"images must be (H, W, 3) uint8 RGB; got {img.shape} "
                                 f"{img.dtype}")
            canvas, lb = letterbox(img, self.config.width, self.config.height)
            canvases.append(canvas)
            boxes.append(lb)
        x = torch.from_numpy(np.stack(canvases)).permute(0, 3, 1, 2).to(self.device)
        logits, ltrb = self.net(x.float() / 255.0)
        out = []
        for (b, s, c), lb, img in zip(postprocess(logits, ltrb, self.points, self.config,
                                                  score_threshold), boxes, images,
                                      strict=True):
            h, w = img.shape[:2]
            b, s, c = b.cpu(), s.cpu(), c.cpu()
            bb = lb.to_image(b.numpy()) if len(b) else np.zeros((0, 4))
            bb[:, [0, 2]] = bb[:, [0, 2]].clip(0, w)
            bb[:, [1, 3]] = bb[:, [1, 3]].clip(0, h)
            out.append(Detections(bb.astype(np.float32), s.numpy(), c.numpy().astype(np.int64)))
        return out

