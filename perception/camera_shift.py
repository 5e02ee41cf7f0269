"""Another camera: a seeded family of camera changes, applied to images already rendered.

A real camera differs from the one a model was trained on in ordinary ways: its white balance
is set for another colour temperature, its exposure and tone curve (gamma) differ, its lens is
slightly out of focus, its sensor adds noise and its encoder JPEG artefacts. A
:class:`CameraShift` is one such camera, drawn from a seed (:meth:`CameraShift.draw`); its
:meth:`CameraShift.apply` turns an image (H, W, 3) uint8 RGB as the renderer delivered it into
the image that camera would have delivered. It is a pure function of the image and the camera:
the sensor noise is drawn from the camera's seed and the image's content, so the same frame
always gives the same picture and two frames get noise of their own.

Depth is a different sensor and is never changed. ``onionsort eval-perception --camera-shift
SEED`` gives each session (and each robot line-up) of a dataset a camera of its own,
``CameraShift.draw((SEED, kind, index))``, and measures perception through it.

Example::

    from perception.camera_shift import CameraShift
    camera = CameraShift.draw(2026)          # one camera; draw((2026, 0, 3)) another
    shifted = camera.apply(rgb)              # (H, W, 3) uint8, same shape
    camera.to_dict()                         # its settings, for a report

The pipeline of :meth:`CameraShift.apply`, in the order a camera applies it: defocus
(Gaussian blur, in linear light), exposure (a gain in stops) and white balance (per-channel
gains, in linear light), the tone curve (sRGB encoding, then ``value ** gamma``), sensor noise
(Gaussian, in grey levels) and JPEG re-encoding.
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import cv2
import numpy as np

__all__ = ["RANGES", "REFERENCE_TEMPERATURE_K", "CameraShift", "white_balance_gains"]

REFERENCE_TEMPERATURE_K = 6500.0
"""The colour temperature the rendered images are white-balanced for (D65, sRGB's white)."""

RANGES: dict[str, tuple[float, float]] = {
    "mired_shift": (12.0, 45.0),   # |shift| of the white balance, in mired (1e6 / kelvin)
    "exposure_ev": (0.15, 0.6),    # |exposure change|, in stops
    "gamma": (0.8, 1.25),          # exponent of the tone curve on [0, 1] values
    "defocus_px": (0.4, 1.0),      # standard deviation of the lens blur, in pixels
    "noise": (1.5, 5.0),           # standard deviation of sensor noise, in grey levels
    "jpeg_quality": (50, 85),      # JPEG quality, inclusive
}
"""What :meth:`CameraShift.draw` draws each setting from (uniformly; white balance and
exposure with a random sign): the differences between two ordinary cameras, not a broken one.
A white balance off by 12-45 mired is about 5,000-5,800 K or 7,400-9,300 K against 6,500 K."""

# linear sRGB from CIE XYZ (IEC 61966-2-1)
_XYZ_TO_RGB = np.array([[3.2406, -1.5372, -0.4986], [-0.9689, 1.8758, 0.0415],
                        [0.0557, -0.2040, 1.0570]])


def _planck_xy(kelvin: float) -> tuple[float, float]:
    """Chromaticity (x, y) of a black body at ``kelvin`` (Kim et al.'s cubic fit of the
    Planckian locus, 1667-25000 K)."""
    t = float(kelvin)
    if not 1667.0 <= t <= 25000.0:
        raise ValueError(f"kelvin must be in [1667, 25000]; got {kelvin}")
    if t <= 4000.0:
        x = -0.2661239e9 / t**3 - 0.2343589e6 / t**2 + 0.8776956e3 / t + 0.179910
    else:
        x = -3.0258469e9 / t**3 + 2.1070379e6 / t**2 + 0.2226347e3 / t + 0.240390
    if t <= 2222.0:
        y = -1.1063814 * x**3 - 1.34811020 * x**2 + 2.18555832 * x - 0.20219683
    elif t <= 4000.0:
        y = -0.9549476 * x**3 - 1.37418593 * x**2 + 2.09137015 * x - 0.16748867
    else:
        y = 3.0817580 * x**3 - 5.87338670 * x**2 + 3.75112997 * x - 0.37001483
    return x, y


def _white(kelvin: float) -> np.ndarray:
    """Linear sRGB (3,) of a black body's white at ``kelvin``, green 1."""
    x, y = _planck_xy(kelvin)
    rgb = _XYZ_TO_RGB @ np.array([x / y, 1.0, (1.0 - x - y) / y])
    return rgb / rgb[1]


def white_balance_gains(kelvin: float) -> np.ndarray:
    """Per-channel gains (3,) in linear light of a camera white-balanced for ``kelvin`` that
    looks at a scene lit at :data:`REFERENCE_TEMPERATURE_K`: white comes out as the
    reference's white over ``kelvin``'s (green 1). Below the reference the picture turns blue,
    above it amber; at the reference the gains are 1."""
    return _white(REFERENCE_TEMPERATURE_K) / _white(kelvin)


def _to_linear(v: np.ndarray) -> np.ndarray:
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def _to_srgb(v: np.ndarray) -> np.ndarray:
    v = np.clip(v, 0.0, 1.0)
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055)


def _seed_words(seed: int | Sequence[int]) -> tuple[int, ...]:
    """``seed`` as a tuple of non-negative ints; one-line errors for anything else."""
    if isinstance(seed, int | np.integer):
        words = (seed,)
    elif isinstance(seed, Sequence) and not isinstance(seed, str) and len(seed):
        words = tuple(seed)
    else:
        words = ()
    if not words or not all(isinstance(w, int | np.integer) and not isinstance(w, bool)
                            for w in words):
        raise TypeError(f"seed must be a non-negative int or a sequence of them; got {seed!r}")
    if any(w < 0 for w in words):
        raise ValueError(f"seed must be a non-negative int or a sequence of them; got {seed!r}")
    return tuple(int(w) for w in words)


@dataclass(frozen=True)
class CameraShift:
    """One camera, as it departs from the renderer's (:mod:`perception.camera_shift`).

    Attributes
    ----------
    temperature_k : float
        The colour temperature its white balance is set for (the scene is lit at
        :data:`REFERENCE_TEMPERATURE_K`).
    exposure_ev : float
        Exposure change in stops (a gain of ``2 ** exposure_ev`` in linear light).
    gamma : float
        Exponent of its tone curve on sRGB values in [0, 1] (> 1 darker mid-tones).
    defocus_px : float
        Standard deviation of its lens blur in pixels (0: sharp).
    noise : float
        Standard deviation of its sensor noise in grey levels (0: none).
    jpeg_quality : int
        JPEG quality of its encoder, in [5, 100]; 0 encodes no JPEG.
    seed : tuple of int
        The seed it was drawn from; with each image's content, it seeds the image's noise.
    """

    temperature_k: float = REFERENCE_TEMPERATURE_K
    exposure_ev: float = 0.0
    gamma: float = 1.0
    defocus_px: float = 0.0
    noise: float = 0.0
    jpeg_quality: int = 0
    seed: tuple[int, ...] = (0,)

    def __post_init__(self) -> None:
        object.__setattr__(self, "seed", _seed_words(self.seed))
        checks = {"temperature_k": (1667.0, 25000.0),  # the Planckian locus' fit
                  "exposure_ev": (-4.0, 4.0), "gamma": (0.2, 5.0), "defocus_px": (0.0, 10.0),
                  "noise": (0.0, 50.0)}
        for name, (low, high) in checks.items():
            if not low <= getattr(self, name) <= high:
                raise ValueError(f"{name} must be in [{low}, {high}]; got "
                                 f"{getattr(self, name)}")
        if self.jpeg_quality != 0 and not 5 <= self.jpeg_quality <= 100:
            raise ValueError(f"jpeg_quality must be 0 (none) or in [5, 100]; got "
                             f"{self.jpeg_quality}")

    @classmethod
    def draw(cls, seed: int | Sequence[int]) -> CameraShift:
        """A camera drawn from :data:`RANGES` by ``seed`` (a non-negative int, or a sequence
        of them such as ``(seed, kind, index)`` for one camera of a family): the same seed
        always gives the same camera."""
        words = _seed_words(seed)
        rng = np.random.default_rng(np.random.SeedSequence(list(words)))
        sign = rng.choice([-1.0, 1.0], size=2)
        mired = 1e6 / REFERENCE_TEMPERATURE_K + sign[0] * rng.uniform(*RANGES["mired_shift"])
        low, high = RANGES["jpeg_quality"]
        return cls(temperature_k=float(1e6 / mired),
                   exposure_ev=float(sign[1] * rng.uniform(*RANGES["exposure_ev"])),
                   gamma=float(rng.uniform(*RANGES["gamma"])),
                   defocus_px=float(rng.uniform(*RANGES["defocus_px"])),
                   noise=float(rng.uniform(*RANGES["noise"])),
                   jpeg_quality=int(rng.integers(low, high + 1)), seed=words)

    def to_dict(self) -> dict:
        """Its settings, JSON-ready."""
        return {**asdict(self), "seed": list(self.seed)}

    def apply(self, image: np.ndarray) -> np.ndarray:
        """``image`` (H, W, 3) uint8 RGB as this camera would have delivered it (a new array,
        same shape and dtype; ``image`` is not changed)."""
        img = np.asarray(image)
        if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
            raise ValueError(f"image must be (H, W, 3) uint8 RGB; got shape {img.shape}, "
                             f"dtype {img.dtype}")
        lin = _to_linear(img.astype(np.float32) / np.float32(255.0))
        if self.defocus_px > 0:
            lin = cv2.GaussianBlur(lin, (0, 0), self.defocus_px,
                                   borderType=cv2.BORDER_REFLECT)
        gains = (2.0 ** self.exposure_ev) * white_balance_gains(self.temperature_k)
        lin = lin * gains.astype(np.float32)
        out = _to_srgb(lin) ** np.float32(self.gamma) * np.float32(255.0)
        if self.noise > 0:
            digest = zlib.crc32(np.ascontiguousarray(img).tobytes())
            rng = np.random.default_rng(np.random.SeedSequence([*self.seed, digest]))
            out = out + rng.normal(0.0, self.noise, out.shape).astype(np.float32)
        out = np.clip(np.rint(out), 0, 255).astype(np.uint8)
        if self.jpeg_quality:
            ok, buf = cv2.imencode(".jpg", np.ascontiguousarray(out[..., ::-1]),
                                   [cv2.IMWRITE_JPEG_QUALITY, int(self.jpeg_quality)])
            if not ok:
                raise RuntimeError("JPEG encoding failed")
            out = cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1]
        return np.ascontiguousarray(out)
