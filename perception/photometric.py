"""Photometric augmentation for training: each sample seen through a camera of its own.

A trained model meets cameras it never saw (another white balance, exposure, tone curve, lens,
sensor, encoder: :mod:`perception.camera_shift`). The training loops (the detector's, the
inspection classifier's, and :mod:`state_abstraction`'s state classifier's) pass each training
sample through :class:`PhotometricAugment`, a new draw of those camera settings each time; no
evaluation, validation or inference path calls it.

It is built from ``torchvision.transforms.v2``: torchvision is a dependency already (the
detector's NMS), its v2 transforms are maintained upstream, work on tensors on any device and
apply one draw to every image of a call, which is what the frames of one step need (one camera
for the three frames the state classifier reads together). kornia and albumentations offer the
same operations and would be new dependencies for nothing more. White balance is not among v2's
transforms; :class:`WhiteBalance` is a v2 transform of our own (per-channel gains in linear
light, as :func:`perception.camera_shift.white_balance_gains` has them), so it composes like
the rest, as do :class:`RandomGamma` and :class:`RandomJPEG` (OpenCV's encoder: torchvision's
own codecs are deprecated).

Layout: images ``x[n, 3, H, W]`` float in [0, 1] (or one image ``[3, H, W]``); the output has
the same shape and dtype.

Example::

    from perception.photometric import PhotometricAugment
    augment = PhotometricAugment()
    x = augment(x)              # x[n, 3, H, W] float in [0, 1]: one camera for all n
"""

from __future__ import annotations

from typing import Any

import torch
from torchvision.transforms import v2
from torchvision.transforms.v2 import functional as F

__all__ = ["PhotometricAugment", "RandomGamma", "RandomJPEG", "WhiteBalance"]


class WhiteBalance(v2.Transform):
    """A white balance off by up to ``mired`` mired (1e6 / kelvin), either way: each channel
    scaled by the gains of a black body that far from the reference
    (:func:`perception.camera_shift.white_balance_gains`, in linear light), applied to the
    encoded values as ``gain ** (1 / 2.2)`` (exact for a power-law encoding of 2.2, and one
    multiplication instead of two conversions)."""

    def __init__(self, mired: float = 45.0) -> None:
        super().__init__()
        if not 0.0 <= mired <= 200.0:
            raise ValueError(f"mired must be in [0, 200]; got {mired}")
        self.mired = float(mired)

    def make_params(self, flat_inputs: list[Any]) -> dict[str, Any]:
        from perception.camera_shift import REFERENCE_TEMPERATURE_K, white_balance_gains

        shift = (torch.rand(()) * 2 - 1).item() * self.mired
        kelvin = 1e6 / (1e6 / REFERENCE_TEMPERATURE_K + shift)
        gains = torch.as_tensor(white_balance_gains(kelvin), dtype=torch.float32)
        return {"gains": gains ** (1 / 2.2)}

    def transform(self, inpt: Any, params: dict[str, Any]) -> Any:
        if not isinstance(inpt, torch.Tensor) or not inpt.is_floating_point():
            return inpt
        return (inpt * params["gains"].to(inpt.device, inpt.dtype).view(3, 1, 1)).clamp(0, 1)


class RandomGamma(v2.Transform):
    """Another tone curve: ``value ** gamma``, gamma uniform in ``gamma``."""

    def __init__(self, gamma: tuple[float, float] = (0.8, 1.25)) -> None:
        super().__init__()
        if not 0.0 < gamma[0] <= gamma[1]:
            raise ValueError(f"gamma must be a range 0 < low <= high; got {gamma}")
        self.gamma = (float(gamma[0]), float(gamma[1]))

    def make_params(self, flat_inputs: list[Any]) -> dict[str, Any]:
        low, high = self.gamma
        return {"gamma": low + (high - low) * torch.rand(()).item()}

    def transform(self, inpt: Any, params: dict[str, Any]) -> Any:
        if not isinstance(inpt, torch.Tensor) or not inpt.is_floating_point():
            return inpt
        return F.adjust_gamma(inpt, params["gamma"])


class RandomJPEG(v2.Transform):
    """JPEG re-encoding at a quality uniform in ``quality`` (inclusive), through OpenCV's
    encoder: torchvision's own image codecs are deprecated (0.29) in favour of a new
    dependency."""

    def __init__(self, quality: tuple[int, int] = (40, 95)) -> None:
        super().__init__()
        if not 1 <= quality[0] <= quality[1] <= 100:
            raise ValueError(f"quality must be a range 1 <= low <= high <= 100; got {quality}")
        self.quality = (int(quality[0]), int(quality[1]))

    def make_params(self, flat_inputs: list[Any]) -> dict[str, Any]:
        low, high = self.quality
        return {"quality": int(torch.randint(low, high + 1, ()).item())}

    def transform(self, inpt: Any, params: dict[str, Any]) -> Any:
        if not isinstance(inpt, torch.Tensor) or not inpt.is_floating_point():
            return inpt
        import cv2

        images = inpt.reshape(-1, *inpt.shape[-3:])
        out = []
        for image in images:
            rgb = (image.detach().clamp(0, 1) * 255).round().byte().permute(1, 2, 0)
            ok, buf = cv2.imencode(".jpg", rgb.cpu().numpy(),
                                   [cv2.IMWRITE_JPEG_QUALITY, params["quality"]])
            if not ok:
                raise RuntimeError("JPEG encoding failed")
            decoded = torch.from_numpy(cv2.imdecode(buf, cv2.IMREAD_UNCHANGED))
            out.append(decoded.reshape(rgb.shape).permute(2, 0, 1))
        return (torch.stack(out).to(inpt.device, inpt.dtype) / 255.0).reshape(inpt.shape)


class PhotometricAugment:
    """A camera of its own for each call: white balance, exposure and contrast, saturation,
    tone curve, at times defocus, sensor noise and JPEG, each drawn afresh from
    torch's generator (seeded by the training loop).

    Parameters
    ----------
    strength : float
        Scales every range (1: ranges that cover :data:`perception.camera_shift.RANGES`
        with room to spare; 0: the identity). The probabilities of blur, noise and JPEG stay.
    """

    def __init__(self, strength: float = 1.0) -> None:
        if not 0.0 <= strength <= 2.0:
            raise ValueError(f"strength must be in [0, 2]; got {strength}")
        self.strength = float(strength)
        s = self.strength
        self.transform = v2.Compose([
            WhiteBalance(mired=60.0 * s),
            v2.ColorJitter(brightness=0.35 * s, contrast=0.2 * s, saturation=0.2 * s),
            RandomGamma((1.0 - 0.25 * s, 1.0 + 0.3 * s)),
            v2.RandomApply([v2.GaussianBlur(5, sigma=(0.1, 0.1 + 1.1 * s))], p=0.5),
            v2.RandomApply([v2.GaussianNoise(mean=0.0, sigma=0.025 * s, clip=True)], p=0.5),
            v2.RandomApply([RandomJPEG((40, 95))], p=0.4),
        ]) if s > 0 else None

    def __call__(self, images: torch.Tensor) -> torch.Tensor:
        """``images`` ``[n, 3, H, W]`` (or ``[3, H, W]``) float in [0, 1] through one camera."""
        if not isinstance(images, torch.Tensor) or images.ndim not in (3, 4) \
                or images.shape[-3] != 3 or not images.is_floating_point():
            raise ValueError(f"images must be a float tensor [n, 3, H, W] or [3, H, W]; got "
                             f"{getattr(images, 'shape', type(images).__name__)}")
        if self.transform is None:
            return images
        dtype = images.dtype
        out = self.transform(images.float())
        return out.clamp(0.0, 1.0).to(dtype)

    def each(self, images: torch.Tensor) -> torch.Tensor:
        """``images`` ``[n, 3, H, W]``, each through a camera of its own (a training loop's
        ``augment``)."""
        return torch.stack([self(image) for image in images])

    def __repr__(self) -> str:
        return f"PhotometricAugment(strength={self.strength})"
