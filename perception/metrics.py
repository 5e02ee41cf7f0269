"""COCO-style mean average precision of the detector.

Layouts: per image, ground truth ``(boxes[G, 4], classes[G])`` and detections ``(boxes[D, 4],
scores[D], classes[D])``, boxes ``[x_min, y_min, x_max, y_max]`` pixels.

The conventions are COCO's (``pycocotools.cocoeval.COCOeval`` with area range "all", 100
detections per image and class, no crowd boxes), so the numbers compare with published ones and
a test checks them against pycocotools: per class and IoU threshold in 0.50:0.05:0.95,
detections are matched greedily in order of score to the unmatched ground truth of highest IoU
at or above the threshold; precision is made monotone and read at 101 recall points; the mean
runs over the classes that have ground truth.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["IOU_THRESHOLDS", "box_iou", "mean_average_precision"]

IOU_THRESHOLDS = np.linspace(0.5, 0.95, 10)
_RECALL_POINTS = np.linspace(0.0, 1.0, 101)


def box_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """IoU ``[len(a), len(b)]`` of two sets of boxes ``[N, 4]``."""
    a, b = np.asarray(a, float).reshape(-1, 4), np.asarray(b, float).reshape(-1, 4)
    lt = np.maximum(a[:, None, :2], b[None, :, :2])
    rb = np.minimum(a[:, None, 2:], b[None, :, 2:])
    inter = np.prod(np.clip(rb - lt, 0, None), axis=2)
    area_a = np.prod(a[:, 2:] - a[:, :2], axis=1)
    area_b = np.prod(b[:, 2:] - b[:, :2], axis=1)
    union = area_a[:, None] + area_b[None, :] - inter
    return np.where(union > 0, inter / np.where(union > 0, union, 1), 0.0)


def _match(iou: np.ndarray, threshold: float) -> np.ndarray:
    """Whether each detection (rows, in score order) matches a ground truth (columns)."""
    taken = np.zeros(iou.shape[1], bool)
    hit = np.zeros(iou.shape[0], bool)
    t = min(threshold, 1 - 1e-10)
    for d in range(iou.shape[0]):
        best, best_iou = -1, t
        for g in range(iou.shape[1]):
            if not taken[g] and iou[d, g] >= best_iou:
                best, best_iou = g, iou[d, g]
        if best >= 0:
            taken[best], hit[d] = True, True
    return hit


def _average_precision(hits: np.ndarray, scores: np.ndarray, n_gt: int) -> float:
    order = np.argsort(-scores, kind="mergesort")
    tp = np.cumsum(hits[order])
    fp = np.cumsum(~hits[order])
    recall = tp / n_gt
    precision = tp / np.maximum(tp + fp, np.spacing(1))
    precision = np.maximum.accumulate(precision[::-1])[::-1] if len(precision) else precision
    idx = np.searchsorted(recall, _RECALL_POINTS, side="left")
    q = np.array([precision[i] if i < len(precision) else 0.0 for i in idx])
    return float(q.mean())


def mean_average_precision(
    ground_truth: Sequence[tuple[np.ndarray, np.ndarray]],
    detections: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]],
    max_detections: int = 100,
    *,
    any_class: bool = False,
) -> dict[str, float]:
    """``{"map50": mAP@0.5, "map50_95": mAP@0.5:0.95, "map75": mAP@0.75}`` over images.

    Parameters
    ----------
    ground_truth : sequence of (boxes [G, 4], classes [G]), one per image
    detections : sequence of (boxes [D, 4], scores [D], classes [D]), one per image
    max_detections : int
        Detections kept per image and class (highest scores), as COCO's maxDets.
    any_class : bool
        Count every box as one class (COCO's ``useCats=0``): how well the objects are found,
        whatever class each is called.
    """
    if len(ground_truth) != len(detections):
        raise ValueError(f"ground_truth and detections must cover the same images; got "
                         f"{len(ground_truth)} and {len(detections)}")
    gts = [(np.asarray(b, float).reshape(-1, 4), np.asarray(c, int).reshape(-1))
           for b, c in ground_truth]
    dts = [(np.asarray(b, float).reshape(-1, 4), np.asarray(s, float).reshape(-1),
            np.asarray(c, int).reshape(-1)) for b, s, c in detections]
    if any_class:
        gts = [(b, np.zeros_like(c)) for b, c in gts]
        dts = [(b, s, np.zeros_like(c)) for b, s, c in dts]
    classes = sorted({int(c) for _, cs in gts for c in cs})
    ap = np.full((len(IOU_THRESHOLDS), len(classes)), np.nan)
    for k, cls in enumerate(classes):
        n_gt = sum(int((c == cls).sum()) for _, c in gts)
        hits = [[] for _ in IOU_THRESHOLDS]
        scores = []
        for (gb, gc), (db, ds, dc) in zip(gts, dts, strict=True):
            g = gb[gc == cls]
            sel = np.nonzero(dc == cls)[0]
            sel = sel[np.argsort(-ds[sel], kind="mergesort")][:max_detections]
            if not len(sel):
                continue
            iou = box_iou(db[sel], g)
            scores.append(ds[sel])
            for t, thr in enumerate(IOU_THRESHOLDS):
                hits[t].append(_match(iou, thr))
        all_scores = np.concatenate(scores) if scores else np.zeros(0)
        for t in range(len(IOU_THRESHOLDS)):
            h = np.concatenate(hits[t]) if hits[t] else np.zeros(0, bool)
            ap[t, k] = _average_precision(h, all_scores, n_gt)
    if not classes:
        return {"map50": float("nan"), "map50_95": float("nan"), "map75": float("nan")}
    return {"map50": float(ap[0].mean()), "map50_95": float(ap.mean()),
            "map75": float(ap[5].mean())}
