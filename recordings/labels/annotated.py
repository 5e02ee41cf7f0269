"""Labelled images as annotation tools hold them, before they become a dataset.

The readers of :mod:`recordings.labels.coco` and :mod:`recordings.labels.yolo` give
:class:`AnnotatedImage`s: an image file, the split it belongs to (None in a set without splits), and
its boxes as ``[x_min, y_min, x_max, y_max]`` in the file's own pixels (exclusive max, as the
dataset's records have them) with the class *names* the tool used. Mapping names to the dataset's
classes, matching state labels and resizing are the importer's (``onionsort label import``).
Splits are named as the dataset names them: Roboflow's ``valid`` is ``val``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

__all__ = ["IMAGE_SUFFIXES", "AnnotatedImage", "BadAnnotations", "LoadedImage", "check_box",
           "load_image", "read_color", "split_name"]

#: Image files the readers take (OpenCV decodes them).
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp")
#: How far (pixels) a box may reach past its image's edge and be clipped to it: tools round.
EDGE_TOLERANCE = 1.0
_SPLIT_ALIASES = {"train": "train", "val": "val", "valid": "val", "validation": "val",
                  "test": "test"}


class BadAnnotations(ValueError):
    """A labelled image set that cannot be read as its format says; the message names the
    file and what is wrong in it."""


@dataclass(frozen=True)
class AnnotatedImage:
    """One labelled image of an annotation tool's set.

    Attributes
    ----------
    split : str or None
        ``train``, ``val`` or ``test``; None where the set has no splits.
    name : str
        The image's file name as the annotations give it (COCO's ``file_name``; for YOLO the
        image file's path under its images folder).
    path : Path
        Where the image file is.
    boxes : tuple of (x_min, y_min, x_max, y_max)
        In the file's pixels.
    labels : tuple of str
        The class name of each box.
    source : str
        The annotation file (or line) the boxes come from, for error messages.
    normalized : bool
        The boxes are in units of the image's width and height (YOLO's), not pixels.
    """

    split: str | None
    name: str
    path: Path
    boxes: tuple[tuple[float, float, float, float], ...]
    labels: tuple[str, ...]
    source: str
    normalized: bool = False

    def pixel_boxes(self, width: int, height: int) -> list[tuple[float, float, float, float]]:
        """The boxes in the pixels of a ``width`` x ``height`` image, each checked
        (:func:`check_box`)."""
        sx, sy = (width, height) if self.normalized else (1, 1)
        return [check_box((b[0] * sx, b[1] * sy, b[2] * sx, b[3] * sy), width, height,
                          f"{self.source}: {self.name}") for b in self.boxes]


def split_name(text: str) -> str | None:
    """The dataset's name of a split as tools name it (``valid`` -> ``val``); None for a
    name that is no split."""
    return _SPLIT_ALIASES.get(text.lower())


def read_color(image: AnnotatedImage) -> np.ndarray:
    """The image's pixels, (H, W, 3) uint8 RGB; a missing or unreadable file is a
    :class:`BadAnnotations` naming the annotation that refers to it."""
    if not image.path.is_file():
        raise BadAnnotations(f"{image.source}: image {image.name!r} is not in the folder "
                             f"(no {image.path})")
    bgr = cv2.imread(str(image.path), cv2.IMREAD_COLOR)
    if bgr is None:
        raise BadAnnotations(f"{image.source}: image {image.path} cannot be decoded")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def check_box(box, width: int, height: int, where: str) -> tuple[float, float, float, float]:
    """``box`` (x_min, y_min, x_max, y_max) checked against a ``width`` x ``height`` image:
    a box that reaches past an edge by up to :data:`EDGE_TOLERANCE` pixels is clipped to it;
    one further out, or empty, is a :class:`BadAnnotations` naming ``where``."""
    x0, y0, x1, y1 = (float(v) for v in box)
    tol = EDGE_TOLERANCE
    if not (x0 >= -tol and y0 >= -tol and x1 <= width + tol and y1 <= height + tol):
        raise BadAnnotations(f"{where}: box [{x0:g}, {y0:g}, {x1:g}, {y1:g}] lies outside its "
                             f"{width}x{height} image")
    x0, y0, x1, y1 = max(x0, 0.0), max(y0, 0.0), min(x1, float(width)), min(y1, float(height))
    if not (x1 > x0 and y1 > y0):
        raise BadAnnotations(f"{where}: box [{x0:g}, {y0:g}, {x1:g}, {y1:g}] is empty")
    return x0, y0, x1, y1


@dataclass(frozen=True)
class LoadedImage:
    """An annotated image made ready for a dataset: ``color`` (H, W, 3) uint8 RGB, ``boxes``
    in its pixels, ``png`` (the file's own bytes where it is a PNG of exactly these pixels,
    else None) and ``depth_mm`` (H, W) uint16 or None."""

    color: np.ndarray
    boxes: list[tuple[float, float, float, float]]
    png: bytes | None
    depth_mm: np.ndarray | None


def load_image(image: AnnotatedImage, fit: tuple[int, int], depth: Path | None = None
               ) -> LoadedImage:
    """Read ``image`` and check its boxes; shrink it (and its boxes, and the depth image
    ``depth``, 16-bit PNG in millimetres of the same size) to fit ``fit`` (width, height)
    keeping its aspect, by area averaging (depth: nearest), where it is larger."""
    color = read_color(image)
    height, width = color.shape[:2]
    boxes = image.pixel_boxes(width, height)
    depth_mm = None
    if depth is not None:
        depth_mm = cv2.imread(str(depth), cv2.IMREAD_UNCHANGED)
        if depth_mm is None or depth_mm.dtype != np.uint16 or depth_mm.shape != (height, width):
            raise BadAnnotations(f"{depth}: depth must be a 16-bit one-channel PNG of the "
                                 f"image's size {width}x{height} (millimetres)")
    scale = min(1.0, fit[0] / width, fit[1] / height)
    if scale < 1.0:
        size = (max(1, round(width * scale)), max(1, round(height * scale)))
        color = cv2.resize(color, size, interpolation=cv2.INTER_AREA)
        sx, sy = size[0] / width, size[1] / height
        boxes = [(b[0] * sx, b[1] * sy, b[2] * sx, b[3] * sy) for b in boxes]
        if depth_mm is not None:
            depth_mm = cv2.resize(depth_mm, size, interpolation=cv2.INTER_NEAREST)
        return LoadedImage(color, boxes, None, depth_mm)
    png = None
    if image.path.suffix.lower() == ".png":
        raw = image.path.read_bytes()
        same = cv2.imdecode(np.frombuffer(raw, np.uint8), cv2.IMREAD_UNCHANGED)
        if same is not None and same.dtype == np.uint8 and same.ndim == 3 and same.shape[2] == 3:
            png = raw  # the file as it is: its pixels, bit for bit
    return LoadedImage(color, boxes, png, depth_mm)
