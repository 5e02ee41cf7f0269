"""The onion detector: a small anchor-free, grid-based, YOLO-style network.

Layouts: images ``x[n, 3, H, W]`` RGB in [0, 1] with ``H, W`` multiples of 32; per level ``i``
(stride ``STRIDES[i]``) the head gives class logits ``[n, C, h_i, w_i]`` and box distances
``[n, 4, h_i, w_i]`` (left, top, right, bottom, in units of the stride); flattened over levels,
``points[P, 2]`` (grid-cell centres in pixels), ``logits[n, P, C]`` and ``ltrb[n, P, 4]``
(pixels). Boxes are ``[x_min, y_min, x_max, y_max]`` pixels.

Architecture (in the spirit of YOLOv8 and FCOS): a CSP backbone of Conv-BN-SiLU layers down to
stride 32, an FPN/PAN neck giving levels at strides 8, 16 and 32, and a decoupled head per level
(one branch for classes, one for box distances) shared across levels. Onions in the main camera
are 7-17 px (stride 8); held up to the inspection view they are several times larger.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
from torch import nn

__all__ = ["STRIDES", "DetectorConfig", "DetectorNet", "grid_points"]

STRIDES = (8, 16, 32)


@dataclass(frozen=True)
class DetectorConfig:
    """Network size, input canvas and inference thresholds."""

    width: int = 320
    height: int = 256
    channels: int = 12
    n_classes: int = 2
    score_threshold: float = 0.25
    iou_threshold: float = 0.6
    max_detections: int = 100

    def __post_init__(self) -> None:
        if self.width % 32 or self.height % 32:
            raise ValueError(f"width and height must be multiples of 32; got "
                             f"{self.width}x{self.height}")

    def to_dict(self) -> dict:
        return asdict(self)


class ConvBN(nn.Sequential):
    """Conv -> BatchNorm -> SiLU."""

    def __init__(self, c_in: int, c_out: int, k: int = 3, s: int = 1) -> None:
        super().__init__(nn.Conv2d(c_in, c_out, k, s, k // 2, bias=False),
                         nn.BatchNorm2d(c_out), nn.SiLU(inplace=True))


class CSPBlock(nn.Module):
    """A C2f-style block: split, ``n`` residual bottlenecks on one half, concatenate, fuse."""

    def __init__(self, c_in: int, c_out: int, n: int = 1) -> None:
        super().__init__()
        h = c_out // 2
        self.split = ConvBN(c_in, 2 * h, 1)
        self.blocks = nn.ModuleList(
            nn.Sequential(ConvBN(h, h, 3), ConvBN(h, h, 3)) for _ in range(n))
        self.fuse = ConvBN((2 + n) * h, c_out, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        a, b = self.split(x).chunk(2, dim=1)
        outs = [a, b]
        for block in self.blocks:
            b = b + block(b)
            outs.append(b)
        return self.fuse(torch.cat(outs, dim=1))


class DetectorNet(nn.Module):
    """Backbone, FPN/PAN neck and a decoupled head over strides 8, 16, 32."""

    def __init__(self, config: DetectorConfig = DetectorConfig()) -> None:
        super().__init__()
        self.config = config
        c = config.channels
        self.stem = nn.Sequential(ConvBN(3, c, 3, 2), ConvBN(c, 2 * c, 3, 2))  # stride 4
        self.down8 = nn.Sequential(ConvBN(2 * c, 4 * c, 3, 2), CSPBlock(4 * c, 4 * c, 2))
        self.down16 = nn.Sequential(ConvBN(4 * c, 8 * c, 3, 2), CSPBlock(8 * c, 8 * c, 2))
        self.down32 = nn.Sequential(ConvBN(8 * c, 8 * c, 3, 2), CSPBlock(8 * c, 8 * c))
        self.up = nn.Upsample(scale_factor=2, mode="nearest")
        self.top16 = CSPBlock(16 * c, 8 * c)
        self.top8 = CSPBlock(12 * c, 4 * c)
        self.bottom16 = nn.Sequential(ConvBN(4 * c, 4 * c, 3, 2))
        self.out16 = CSPBlock(12 * c, 8 * c)
        self.bottom32 = nn.Sequential(ConvBN(8 * c, 8 * c, 3, 2))
        self.out32 = CSPBlock(16 * c, 8 * c)
        h = 4 * c
        self.proj = nn.ModuleList([ConvBN(4 * c, h, 1), ConvBN(8 * c, h, 1), ConvBN(8 * c, h, 1)])
        self.cls_branch = nn.Sequential(ConvBN(h, h), ConvBN(h, h),
                                        nn.Conv2d(h, config.n_classes, 1))
        self.box_branch = nn.Sequential(ConvBN(h, h), ConvBN(h, h), nn.Conv2d(h, 4, 1))
        self.scales = nn.Parameter(torch.ones(len(STRIDES)))
        prior = 0.01  # initial foreground probability, as in RetinaNet/FCOS
        nn.init.constant_(self.cls_branch[-1].bias, -float(torch.log(torch.tensor(
            (1 - prior) / prior))))

    def features(self, x: torch.Tensor) -> list[torch.Tensor]:
        c4 = self.stem(x)
        c8 = self.down8(c4)
        c16 = self.down16(c8)
        c32 = self.down32(c16)
        p16 = self.top16(torch.cat([self.up(c32), c16], 1))
        p8 = self.top8(torch.cat([self.up(p16), c8], 1))
        n16 = self.out16(torch.cat([self.bottom16(p8), p16], 1))
        n32 = self.out32(torch.cat([self.bottom32(n16), c32], 1))
        return [p8, n16, n32]

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``logits[n, P, C]`` and ``ltrb[n, P, 4]`` (pixels, >= 0) over all levels."""
        logits, ltrb = [], []
        for i, (f, stride) in enumerate(zip(self.features(x), STRIDES, strict=True)):
            f = self.proj[i](f)
            cls = self.cls_branch(f)
            box = nn.functional.softplus(self.box_branch(f) * self.scales[i]) * stride
            logits.append(cls.flatten(2).transpose(1, 2))
            ltrb.append(box.flatten(2).transpose(1, 2))
        return torch.cat(logits, 1), torch.cat(ltrb, 1)


def grid_points(height: int, width: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Cell centres ``points[P, 2]`` (x, y pixels) and their strides ``[P]``, level by level."""
    points, strides = [], []
    for s in STRIDES:
        ys, xs = torch.meshgrid(torch.arange(height // s), torch.arange(width // s),
                                indexing="ij")
        pts = torch.stack([xs, ys], -1).reshape(-1, 2).float() * s + s / 2
        points.append(pts)
        strides.append(torch.full((len(pts),), float(s)))
    return torch.cat(points), torch.cat(strides)
