"""Label assignment and the training loss of the detector.

Layouts: ``points[P, 2]`` grid-cell centres (x, y) and ``strides[P]``; per image, ground truth
``gt_boxes[G, 4]`` (x_min, y_min, x_max, y_max pixels) and ``gt_classes[G]``; the assignment
``matched[P]`` is the index of the ground-truth box each point regresses, or -1 for background.

Assignment (FCOS-style, with YOLO's guarantee of a positive per object): a point is a candidate
for a box if it lies inside the box, within ``radius`` strides of the box centre, and on the
level whose scale range holds the box's size; among several boxes a point takes the smallest.
Onions of 7 px can fall between the centres of stride-8 cells, so every box also claims the cell
of its level nearest its centre. The loss is the sigmoid focal loss on class scores of every
point plus the GIoU loss of the decoded boxes at positive points, both normalised by the number
of positives.
"""

from __future__ import annotations

import torch
from torchvision.ops import generalized_box_iou_loss, sigmoid_focal_loss

__all__ = ["assign", "decode", "detection_loss"]

#: Box size (longest side, pixels) handled by each level, strides 8, 16, 32.
SIZE_RANGES = ((0.0, 40.0), (40.0, 96.0), (96.0, float("inf")))


def decode(points: torch.Tensor, ltrb: torch.Tensor) -> torch.Tensor:
    """Boxes ``[..., P, 4]`` from points ``[P, 2]`` and distances ``ltrb[..., P, 4]``."""
    return torch.cat([points - ltrb[..., :2], points + ltrb[..., 2:]], dim=-1)


def assign(points: torch.Tensor, strides: torch.Tensor, gt_boxes: torch.Tensor,
           radius: float = 1.5) -> torch.Tensor:
    """``matched[P]``: the ground-truth index of each point, -1 for background."""
    n_points, n_gt = len(points), len(gt_boxes)
    matched = torch.full((n_points,), -1, dtype=torch.long)
    if n_gt == 0:
        return matched
    x, y = points[:, 0:1], points[:, 1:2]                                   # [P, 1]
    x0, y0, x1, y1 = gt_boxes.T                                              # [G] each
    inside = (x > x0) & (x < x1) & (y > y0) & (y < y1)                       # [P, G]
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    r = radius * strides[:, None]
    central = ((x - cx).abs() <= r) & ((y - cy).abs() <= r)
    size = torch.maximum(x1 - x0, y1 - y0)
    level = torch.zeros(n_gt, dtype=torch.long)
    for i, (lo, _) in enumerate(SIZE_RANGES):
        level[size > lo] = i
    level_stride = torch.tensor([8.0, 16.0, 32.0])[level]                    # [G]
    on_level = strides[:, None] == level_stride[None, :]
    candidate = inside & central & on_level
    # the nearest cell of the box's level is always a candidate
    dist = (x - cx) ** 2 + (y - cy) ** 2
    dist = torch.where(on_level, dist, torch.full_like(dist, float("inf")))
    candidate[dist.argmin(dim=0), torch.arange(n_gt)] = True
    area = ((x1 - x0) * (y1 - y0))[None, :].expand(n_points, n_gt)
    area = torch.where(candidate, area, torch.full_like(area, float("inf")))
    best_area, best = area.min(dim=1)
    matched[torch.isfinite(best_area)] = best[torch.isfinite(best_area)]
    return matched


def detection_loss(logits: torch.Tensor, ltrb: torch.Tensor, points: torch.Tensor,
                   strides: torch.Tensor, targets: list[tuple[torch.Tensor, torch.Tensor]]
                   ) -> tuple[torch.Tensor, dict]:
    """Focal + GIoU loss of a batch.

    Parameters
    ----------
    logits : Tensor [n, P, C]
    ltrb : Tensor [n, P, 4]
    points, strides : the grid (see :func:`perception.model.grid_points`)
    targets : list of (gt_boxes [G, 4], gt_classes [G]) per image
    """
    cls_target = torch.zeros_like(logits)
    pos_boxes, pos_pred = [], []
    for i, (boxes, classes) in enumerate(targets):
        matched = assign(points, strides, boxes)
        pos = matched >= 0
        if pos.any():
            cls_target[i, pos, classes[matched[pos]]] = 1.0
            pos_boxes.append(boxes[matched[pos]])
            pos_pred.append(decode(points[pos], ltrb[i, pos]))
    n_pos = max(1.0, float(sum(len(b) for b in pos_boxes)))
    cls_loss = sigmoid_focal_loss(logits, cls_target, reduction="sum") / n_pos
    if pos_boxes:
        box_loss = generalized_box_iou_loss(torch.cat(pos_pred), torch.cat(pos_boxes),
                                            reduction="sum") / n_pos
    else:
        box_loss = ltrb.sum() * 0.0
    loss = cls_loss + 2.0 * box_loss
    return loss, {"cls": cls_loss.item(), "box": box_loss.item(), "positives": n_pos}
