"""Onions: their appearance (size, skin colour, blemishes) and their procedural textures.

Good and blemished onions differ by texture: a blemished onion carries dark rot patches and
bruises, a good one only faint veins. Both vary in radius, skin hue and brightness, so telling
them apart from a 320x240 image is a real perception task. Textures are images ``tex[v, u, c]``
of shape (H, W, 3), uint8 RGB.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["OnionAppearance", "blemish_mask", "onion_texture", "sample_appearance",
           "save_texture"]

#: Skin colours (RGB, 0-255) the hue is drawn around: golden, brown, red onion.
_SKINS = np.array([[196, 150, 72], [170, 112, 58], [150, 60, 70]], float)


@dataclass(frozen=True)
class OnionAppearance:
    """How one onion looks.

    Attributes
    ----------
    blemished : bool
        The onion's true class.
    radius : float
        Radius in metres.
    skin : ndarray of shape (3,)
        Base skin colour, RGB in [0, 255].
    texture_seed : int
        Seed of the texture's pattern (veins, blemishes).
    """

    blemished: bool
    radius: float
    skin: np.ndarray
    texture_seed: int


def sample_appearance(rng: np.random.Generator, blemished: bool) -> OnionAppearance:
    """Draw an onion's size, skin colour and texture pattern."""
    base = _SKINS[rng.choice(len(_SKINS), p=[0.55, 0.3, 0.15])]
    skin = np.clip(base * rng.uniform(0.8, 1.15) + rng.normal(0.0, 10.0, 3), 0, 255)
    return OnionAppearance(
        blemished=bool(blemished),
        radius=float(rng.uniform(0.032, 0.045)),
        skin=skin,
        texture_seed=int(rng.integers(2**31)),
    )


def _blob(shape: tuple[int, int], center: np.ndarray, radius: float, rng) -> np.ndarray:
    """A soft irregular blob mask in [0, 1], shape (H, W)."""
    h, w = shape
    v, u = np.mgrid[0:h, 0:w]
    du = np.minimum(np.abs(u - center[0]), w - np.abs(u - center[0]))  # wraps around in u
    dv = v - center[1]
    angle = np.arctan2(dv, du)
    wobble = 1.0 + 0.3 * np.sin(3 * angle + rng.uniform(0, 2 * np.pi))
    r = np.sqrt(du**2 + dv**2) / (radius * wobble)
    return np.clip(1.5 - r, 0.0, 1.0)


def _patches(appearance: OnionAppearance, size: int, subtlety: float, one_sided: float):
    """The texture's veined skin (size, size, 3) float and its rot patches, each ``(mask
    (size, size) in [0, 1], darkness, kept)``: every patch is drawn (so the random stream is
    the same at every difficulty), the subtle ones fainter and smaller, and only ``kept``
    ones are painted."""
    if size < 16:
        raise ValueError(f"size must be >= 16; got {size}")
    if not 0.0 <= subtlety <= 1.0 or not 0.0 <= one_sided <= 1.0:
        raise ValueError(f"subtlety and one_sided must be in [0, 1]; got {subtlety}, "
                         f"{one_sided}")
    rng = np.random.default_rng(appearance.texture_seed)
    v, u = np.mgrid[0:size, 0:size] / size
    veins = 0.08 * np.sin(2 * np.pi * (u * rng.integers(8, 16) + 0.3 * np.sin(2 * np.pi * v)))
    shade = 1.0 + veins[..., None] + rng.normal(0.0, 0.04, (size, size, 1))
    skin = appearance.skin[None, None, :] * shade
    patches = []
    if appearance.blemished:
        n = int(rng.integers(5, 10))
        keep, sector, start = n, 1.0, 0.0
        if subtlety or one_sided:
            keep = max(1, round(n * (1.0 - 0.8 * subtlety)))
            side = np.random.default_rng([appearance.texture_seed, 1])
            if side.random() < one_sided:
                sector, start = 1.0 / 3.0, side.uniform(0.0, 1.0)
        for k in range(n):
            # one patch per sector around the onion
            u0 = ((start + sector * (k + rng.uniform(0.0, 1.0)) / n) % 1.0) * size
            center = np.array([u0, rng.uniform(0.15 * size, 0.85 * size)])
            radius = rng.uniform(0.1, 0.2) * size * (1.0 - 0.6 * subtlety)
            mask = _blob((size, size), center, radius, rng)
            darkness = rng.uniform(0.75, 0.95) * (1.0 - 0.65 * subtlety)
            patches.append((mask, darkness, k < keep))
    return skin, patches


def onion_texture(appearance: OnionAppearance, size: int = 128, *, subtlety: float = 0.0,
                  one_sided: float = 0.0) -> np.ndarray:
    """The onion's texture, shape (size, size, 3), uint8 RGB.

    Veins run along ``u`` (around the onion); a blemished onion gets 5-9 dark rot patches of
    varied size and darkness, spread so that some show from any side (the camera sees one
    hemisphere, and a sorter one view of it).

    ``subtlety`` in [0, 1] (:attr:`robot.difficulty.Difficulty.blemish_subtlety`) keeps fewer,
    smaller and fainter patches: at 1, a fifth of them (at least one), 40 % of the size and
    35 % of the darkness. ``one_sided`` is the probability (drawn from the texture's seed) that
    every patch lies on one third of the circumference. At 0 and 0 the texture is unchanged.
    """
    tex, patches = _patches(appearance, size, subtlety, one_sided)
    rot = np.array([45.0, 32.0, 20.0])
    for mask, darkness, kept in patches:
        if kept:
            tex = tex * (1 - darkness * mask[..., None]) + rot * darkness * mask[..., None]
    return np.clip(tex, 0, 255).astype(np.uint8)


def blemish_mask(appearance: OnionAppearance, size: int = 128, *, subtlety: float = 0.0,
                 one_sided: float = 0.0) -> np.ndarray:
    """Where :func:`onion_texture` (same arguments) painted rot: (size, size) bool, the texels
    that at least one painted patch darkens at half its strength or more (none for a good
    onion). Rendered in place of the texture, it shows which pixels of a view see rot."""
    _, patches = _patches(appearance, size, subtlety, one_sided)
    out = np.zeros((size, size), bool)
    for mask, _, kept in patches:
        if kept:
            out |= mask >= 0.5
    return out


def save_texture(texture: np.ndarray, path: Path) -> Path:
    """Write ``texture`` (H, W, 3) RGB as a PNG that PyBullet can load; returns ``path``."""
    import cv2

    path = Path(path)
    if not cv2.imwrite(str(path), np.ascontiguousarray(texture[..., ::-1])):
        raise OSError(f"could not write texture {path}")
    return path
