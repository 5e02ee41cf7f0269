"""Where the onion is in an inspection view: the detector's box the inspection reads.

Layouts: a view (H, W, 3) uint8 RGB; boxes ``[D, 4]`` (x_min, y_min, x_max, y_max) pixels with
their ``scores[D]``. Free of torch, so that what draws the inspection's boxes (the evaluation's
Rerun log) picks the same box without loading a network.
"""

from __future__ import annotations

import numpy as np

__all__ = ["INSPECTION_SCORE", "best_box", "view_centre"]

INSPECTION_SCORE = 0.2
"""Minimum detector score for an onion in an inspection view to count as found."""


def best_box(detections, at: tuple[float, float] | None = None) -> np.ndarray | None:
    """The onion's box (4,) among one view's ``detections`` (:class:`perception.Detections`):
    the best of either class if it scores :data:`INSPECTION_SCORE` or more, else None.

    ``at`` is a point (x, y) where the onion is known to be, as in a held onion's view, which
    the hand holds at the middle (:func:`view_centre`): the best of the boxes that hold it is
    the onion's, so that a box elsewhere (a part of the arm) cannot take its place; where no
    box scoring enough holds the point, the best box anywhere."""
    scores = np.asarray(detections.scores, float).reshape(-1)
    if scores.size == 0 or scores.max() < INSPECTION_SCORE:
        return None
    boxes = np.asarray(detections.boxes, float).reshape(-1, 4)
    if at is not None:
        x, y = at
        holds = ((boxes[:, 0] <= x) & (x <= boxes[:, 2]) & (boxes[:, 1] <= y)
                 & (y <= boxes[:, 3]) & (scores >= INSPECTION_SCORE))
        if holds.any():
            scores = np.where(holds, scores, -np.inf)
    return np.asarray(detections.boxes)[int(scores.argmax())]


def view_centre(view: np.ndarray) -> tuple[float, float]:
    """The middle (x, y) of a view (H, W, ...) in pixels: where the Sawyer holds the onion it
    inspects in each of its views."""
    h, w = view.shape[:2]
    return w / 2.0, h / 2.0
