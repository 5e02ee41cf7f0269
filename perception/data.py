"""Detector data: letterboxing onto the input canvas, augmentation, samples of labelled images.

Layouts: images (H, W, 3) uint8 RGB; boxes ``[G, 4]`` float (x_min, y_min, x_max, y_max)
pixels; classes ``[G]`` int (0 good, 1 blemished); tensors ``x[n, 3, H, W]`` in [0, 1].

This package reads no dataset: training takes labelled images, ``(image, boxes, classes)``
triples; which images of a dataset to train on is the ``train`` stage's choice
(:mod:`onionsort.stages.train`).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike

__all__ = ["LabelledImage", "Letterbox", "Sample", "augment", "letterbox", "to_canvas",
           "to_samples"]

#: A labelled image: (image (H, W, 3) uint8 RGB, boxes ``[G, 4]`` pixels, classes ``[G]``).
LabelledImage = tuple[np.ndarray, ArrayLike, ArrayLike]

PAD_VALUE = 114


@dataclass(frozen=True)
class Letterbox:
    """How an image was placed on the canvas: ``canvas = image * scale + (pad_x, pad_y)``."""

    scale: float
    pad_x: float
    pad_y: float

    def to_image(self, boxes: np.ndarray) -> np.ndarray:
        """Boxes ``[G, 4]`` from canvas pixels back to the original image's pixels."""
        b = np.asarray(boxes, float).copy()
        b[:, [0, 2]] = (b[:, [0, 2]] - self.pad_x) / self.scale
        b[:, [1, 3]] = (b[:, [1, 3]] - self.pad_y) / self.scale
        return b


def letterbox(image: np.ndarray, width: int, height: int) -> tuple[np.ndarray, Letterbox]:
    """Resize ``image`` to fit ``width`` x ``height`` keeping its aspect, pad the rest."""
    h, w = image.shape[:2]
    scale = min(width / w, height / h)
    nw, nh = round(w * scale), round(h * scale)
    resized = image if (nw, nh) == (w, h) else cv2.resize(
        image, (nw, nh), interpolation=cv2.INTER_LINEAR if scale > 1 else cv2.INTER_AREA)
    canvas = np.full((height, width, 3), PAD_VALUE, np.uint8)
    px, py = (width - nw) // 2, (height - nh) // 2
    canvas[py:py + nh, px:px + nw] = resized
    return canvas, Letterbox(scale, px, py)


@dataclass
class Sample:
    """One training image on the canvas with its boxes and classes."""

    image: np.ndarray
    boxes: np.ndarray
    classes: np.ndarray


def to_canvas(image: np.ndarray, boxes, classes, width: int, height: int) -> Sample:
    """Letterbox an image and its boxes onto the canvas."""
    canvas, lb = letterbox(image, width, height)
    b = np.asarray(boxes, np.float32).reshape(-1, 4) * lb.scale
    b[:, [0, 2]] += lb.pad_x
    b[:, [1, 3]] += lb.pad_y
    return Sample(canvas, b, np.asarray(classes, np.int64).reshape(-1))


def augment(sample: Sample, rng: np.random.Generator, *, scale: tuple[float, float] = (0.8, 1.25),
            translate: float = 0.1, flip: float = 0.5, color: float = 0.08,
            min_size: float = 2.0) -> Sample:
    """Random flip, scale and translation (boxes follow), and a mild hue/saturation/value jitter.

    The colour jitter stays small on purpose: colour is what tells a blemished onion (darker,
    browner) from a good one at 14 px, and the scene's own lighting already varies. Boxes pushed
    partly off the canvas are clipped; those left smaller than ``min_size`` pixels are dropped.
    """
    img, boxes = sample.image, sample.boxes.copy()
    h, w = img.shape[:2]
    if rng.random() < flip:
        img = img[:, ::-1]
        boxes[:, [0, 2]] = w - boxes[:, [2, 0]]
    s = rng.uniform(*scale)
    tx, ty = rng.uniform(-translate, translate, 2) * (w, h)
    M = np.array([[s, 0, (1 - s) * w / 2 + tx], [0, s, (1 - s) * h / 2 + ty]], np.float32)
    img = cv2.warpAffine(np.ascontiguousarray(img), M, (w, h), flags=cv2.INTER_LINEAR,
                         borderValue=(PAD_VALUE,) * 3)
    boxes = boxes * s
    boxes[:, [0, 2]] += M[0, 2]
    boxes[:, [1, 3]] += M[1, 2]
    boxes[:, [0, 2]] = boxes[:, [0, 2]].clip(0, w)
    boxes[:, [1, 3]] = boxes[:, [1, 3]].clip(0, h)
    keep = ((boxes[:, 2] - boxes[:, 0]) >= min_size) & ((boxes[:, 3] - boxes[:, 1]) >= min_size)
    if color > 0:
        hsv = cv2.cvtColor(img, cv2.COLOR_RGB2HSV).astype(np.float32)
        gain = 1 + rng.uniform(-color, color, 3) * (0.1, 1.0, 1.0)
        hsv[..., 0] = (hsv[..., 0] * gain[0]) % 180
        hsv[..., 1:] = (hsv[..., 1:] * gain[1:]).clip(0, 255)
        img = cv2.cvtColor(hsv.astype(np.uint8), cv2.COLOR_HSV2RGB)
    return Sample(img, boxes[keep], sample.classes[keep])


def to_samples(images: Iterable[LabelledImage], width: int, height: int) -> list[Sample]:
    """Canvas samples of labelled images, in order.

    Parameters
    ----------
    images : iterable of (image, boxes, classes)
        ``image`` (H, W, 3) uint8 RGB, ``boxes`` ``[G, 4]`` pixels (may be empty), ``classes``
        ``[G]``. The same triple object given several times (to oversample it) becomes the same
        :class:`Sample`, so repeats cost no memory.
    width, height : int
        The canvas.

    Returns
    -------
    list of Sample
    """
    if width < 1 or height < 1:
        raise ValueError(f"width and height must be >= 1; got {width}, {height}")
    made: dict[int, tuple[object, Sample]] = {}  # id -> (the triple, kept alive, its sample)
    samples = []
    for triple in images:
        seen = made.get(id(triple))
        if seen is None or seen[0] is not triple:
            image, boxes, classes = triple
            if np.ndim(image) != 3 or np.shape(image)[2] != 3:
                raise ValueError(f"images must be (H, W, 3) RGB; got shape {np.shape(image)}")
            seen = made[id(triple)] = (triple, to_canvas(image, boxes, classes, width, height))
        samples.append(seen[1])
    return samples
