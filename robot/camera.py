"""RGB-D cameras rendered with PyBullet's TinyRenderer (headless), and ground truth from them.

Image layouts: ``rgb[v, u, c]`` (H, W, 3) uint8; ``depth[v, u]`` (H, W) float32 metres along
the optical axis; ``seg[v, u]`` (H, W) int32 body unique id, -1 for background. Boxes are
``(x_min, y_min, x_max, y_max)`` in pixels, inclusive-exclusive (``x_max = last column + 1``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pybullet as p

__all__ = [
    "CameraImage",
    "CameraSpec",
    "Lighting",
    "boxes_from_segmentation",
    "frustum_planes",
    "intrinsics",
    "links_outside",
    "occluded_fraction",
    "render",
    "sample_lighting",
]


@dataclass(frozen=True)
class CameraSpec:
    """A pinhole camera: resolution, vertical field of view, clipping planes and pose."""

    width: int = 320
    height: int = 240
    fov_deg: float = 44.0
    near: float = 0.05
    far: float = 5.0
    eye: tuple[float, float, float] = (0.1, -1.5, 1.5)
    target: tuple[float, float, float] = (0.15, 0.25, 1.08)
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)
    frame_id: str = "camera"

    def __post_init__(self) -> None:
        if self.width < 8 or self.height < 8:
            raise ValueError(
                f"width and height must be >= 8; got {self.width}x{self.height}"
            )
        if not 0.0 < self.near < self.far:
            raise ValueError(f"need 0 < near < far; got near={self.near}, far={self.far}")
        if not 1.0 <= self.fov_deg <= 170.0:
            raise ValueError(f"fov_deg must be in [1, 170]; got {self.fov_deg}")


@dataclass(frozen=True)
class Lighting:
    """TinyRenderer lighting: direction (3,), colour (3,) in [0, 1] and Phong coefficients."""

    direction: tuple[float, float, float] = (0.4, -0.6, 1.0)
    color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    ambient: float = 0.6
    diffuse: float = 0.35
    specular: float = 0.05


def sample_lighting(rng: np.random.Generator) -> Lighting:
    """Draw a lighting condition: direction, a warm-to-cool tint and brightness."""
    direction = rng.uniform([-1.0, -1.0, 0.6], [1.0, 0.2, 1.5])
    warmth = rng.uniform(-0.12, 0.12)
    color = np.clip([1.0 + warmth, 1.0, 1.0 - warmth], 0.0, 1.0)
    return Lighting(
        direction=tuple(direction.round(4).tolist()),
        color=tuple(color.round(4).tolist()),
        ambient=float(rng.uniform(0.45, 0.7)),
        diffuse=float(rng.uniform(0.25, 0.45)),
        specular=float(rng.uniform(0.0, 0.1)),
    )


def intrinsics(spec: CameraSpec) -> np.ndarray:
    """The pinhole matrix ``K`` (3, 3) of ``spec`` (square pixels, principal point at centre)."""
    fy = 0.5 * spec.height / np.tan(np.deg2rad(spec.fov_deg) / 2)
    return np.array([[fy, 0.0, spec.width / 2], [0.0, fy, spec.height / 2], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class CameraImage:
    """One rendered view: ``rgb`` (H, W, 3) uint8, ``depth`` (H, W) float32 m, ``seg`` (H, W);
    ``covered`` (H, W) bool, where a hand drawn over the picture after rendering hides what
    ``seg`` says is there (None: nothing hidden)."""

    rgb: np.ndarray = field(repr=False)
    depth: np.ndarray = field(repr=False)
    seg: np.ndarray = field(repr=False)
    covered: np.ndarray | None = field(default=None, repr=False)


def render(client: int, spec: CameraSpec, lighting: Lighting = Lighting(), *,
           cull: tuple[int, ...] = ()) -> CameraImage:
    """Render ``spec``'s view in physics client ``client`` with the TinyRenderer.

    ``cull`` names bodies whose links lying wholly outside the view are left out of the
    rendering (:func:`links_outside`): the TinyRenderer transforms every triangle of every
    body whatever the camera sees, and a robot's meshes are most of the scene's triangles. The
    picture is the same (a test renders both).
    """
    view = p.computeViewMatrix(spec.eye, spec.target, spec.up, physicsClientId=client)
    proj = p.computeProjectionMatrixFOV(
        spec.fov_deg, spec.width / spec.height, spec.near, spec.far, physicsClientId=client
    )
    hidden = [hide for body in cull for hide in links_outside(client, spec, body)]
    try:
        for body, link, _ in hidden:
            p.changeVisualShape(body, link, rgbaColor=[1, 1, 1, 0], physicsClientId=client)
        w, h, rgba, zbuf, seg = p.getCameraImage(
            spec.width, spec.height, view, proj,
            renderer=p.ER_TINY_RENDERER, shadow=0,
            lightDirection=lighting.direction, lightColor=lighting.color,
            lightAmbientCoeff=lighting.ambient, lightDiffuseCoeff=lighting.diffuse,
            lightSpecularCoeff=lighting.specular,
            physicsClientId=client,
        )
    finally:
        for body, link, color in hidden:
            p.changeVisualShape(body, link, rgbaColor=list(color), physicsClientId=client)
    rgb = np.asarray(rgba, np.uint8).reshape(h, w, 4)[..., :3].copy()
    zbuf = np.asarray(zbuf, np.float32).reshape(h, w)
    depth = (spec.far * spec.near / (spec.far - (spec.far - spec.near) * zbuf)).astype(np.float32)
    return CameraImage(rgb=rgb, depth=depth, seg=np.asarray(seg, np.int32).reshape(h, w))


def frustum_planes(spec: CameraSpec) -> np.ndarray:
    """The six planes (6, 4) of ``spec``'s view frustum in the world: a point ``x`` (3,) is in
    view where ``planes @ [x, 1] >= 0`` for all six."""
    view = np.array(p.computeViewMatrix(spec.eye, spec.target, spec.up)).reshape(4, 4).T
    proj = np.array(p.computeProjectionMatrixFOV(
        spec.fov_deg, spec.width / spec.height, spec.near, spec.far)).reshape(4, 4).T
    m = proj @ view
    return np.array([m[3] + m[0], m[3] - m[0], m[3] + m[1], m[3] - m[1], m[3] + m[2],
                     m[3] - m[2]])


def links_outside(client: int, spec: CameraSpec, body: int
                  ) -> list[tuple[int, int, tuple[float, ...]]]:
    """``(body, link, rgba)`` of each link of ``body`` that ``spec`` cannot see: its bounding
    box lies wholly on the outer side of one of the view's planes. Only links with one visual
    shape count (their colour can be put back as it was)."""
    planes = frustum_planes(spec)
    shapes: dict[int, list] = {}
    for data in p.getVisualShapeData(body, physicsClientId=client):
        shapes.setdefault(int(data[1]), []).append(tuple(data[7]))
    out = []
    for link, colors in shapes.items():
        if len(colors) != 1 or colors[0][3] == 0:
            continue
        lo, hi = (np.asarray(c) for c in p.getAABB(body, link, physicsClientId=client))
        corners = np.array([[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                            for z in (lo[2], hi[2])])
        if np.any(np.all(corners @ planes.T < 0, axis=0)):
            out.append((body, link, colors[0]))
    return out


def boxes_from_segmentation(
    seg: np.ndarray, body_ids: list[int] | np.ndarray
) -> dict[int, tuple[int, int, int, int, int]]:
    """Exact boxes of the visible bodies in a segmentation image.

    Parameters
    ----------
    seg : ndarray of shape (H, W)
        Body unique id per pixel (-1 for background).
    body_ids : sequence of int
        The bodies to box.

    Returns
    -------
    dict
        ``body_id -> (x_min, y_min, x_max, y_max, n_pixels)`` for each body with at least one
        visible pixel; ``x_max``/``y_max`` are exclusive.
    """
    seg = np.asarray(seg)
    if seg.ndim != 2:
        raise ValueError(f"seg must be 2-D (H, W); got shape {seg.shape}")
    boxes: dict[int, tuple[int, int, int, int, int]] = {}
    wanted = np.asarray(list(body_ids), dtype=seg.dtype)
    present = np.intersect1d(np.unique(seg), wanted)
    for body in present.tolist():
        v, u = np.nonzero(seg == body)
        boxes[int(body)] = (
            int(u.min()), int(v.min()), int(u.max()) + 1, int(v.max()) + 1, int(u.size)
        )
    return boxes


def occluded_fraction(seg: np.ndarray, occluder_ids: list[int] | np.ndarray) -> float:
    """Fraction of the view's pixels covered by the occluder bodies, in [0, 1]."""
    seg = np.asarray(seg)
    return float(np.isin(seg, np.asarray(list(occluder_ids), dtype=seg.dtype)).mean())
