"""Perception difficulty: what a real camera and a real line add to the clean rendered world.

A :class:`Difficulty` holds knobs, each a number with a unit and a range; ``0`` turns a knob off.
The named levels :data:`DIFFICULTY_LEVELS` are ``clean`` (today's world, bit for bit),
``realistic`` (a good industrial camera on a tidy line), ``paper`` (what the paper's real camera
and line brought: the level the calibrated (state, action) error rate of ~0.30 is aimed at) and
``hard`` (a poor camera on a busy line). The knob values were chosen on the held-out dataset of
seed 31 only.

Where each knob acts:

- **blemishes** (``blemish_subtlety``, ``one_sided_blemish``): the texture of a blemished onion
  (:func:`robot.onions.onion_texture`) gets fewer, smaller, fainter rot patches, and sometimes
  all of them on one third of its circumference, so one side of it looks good;
- **post-render image effects** (:class:`ImageEffects`), on the main camera and the inspection
  view alike, in this order: lighting (a per-session gain and colour cast, and a slow sinusoidal
  drift of the gain over the session), motion blur (main camera frames in motion only: every
  frame of a step but its first, at-rest one), sensor noise (Gaussian read noise plus shot noise
  whose variance grows with the intensity), JPEG re-encoding; depth gets Gaussian noise;
- **the hand at inspection** (``hand_cover``, ``hand_cover_rate``): the renderer's hand holds
  the onion from above and behind, out of the inspection view, so a real hand's fingers wrapped
  around it are drawn as a patch: a skin-coloured (the sorter's skin; at the station the grey of
  the Sawyer's gripper) ellipse over the onion's box from one side. Box labels keep the whole
  onion;
- **partial passers-by** (``partial_occlusion``): at steps the full passer-by does not cross, a
  passer-by walks past at the edge of the view (:meth:`robot.occluder.PasserBy.start_crossing`
  with ``partial=True``), covering part of the frame but not the workspace. Such steps stay
  labelled *unoccluded*: the ground-truth ``occluded`` flag keeps meaning "the passer-by crossed
  the view in front of the workspace during the step" (a full crossing); every frame's
  ``occluded_fraction`` still says how much of it any passer-by covered.

All randomness comes from a generator seeded from the session's seed
(:func:`difficulty_rng`), separate from the streams the clean world draws from, so the clean
parts of a session (its states, actions, onions and full crossings) are the same at every level.
"""

from __future__ import annotations

import copy
from dataclasses import asdict, dataclass, fields

import numpy as np

__all__ = ["DIFFICULTY_LEVELS", "Difficulty", "ImageEffects", "difficulty_rng",
           "hand_patch", "resolve_difficulty", "tagged_rng", "view_rng"]

#: spawn-key tag of the difficulty's generator (kept apart from the session's own streams)
_TAG = 0xD1FF


@dataclass(frozen=True)
class Difficulty:
    """The knobs of perception difficulty; every knob at 0 is today's clean world.

    Attributes
    ----------
    name : str
        The level's name (``"custom"`` for an unnamed mix).
    blemish_subtlety : float, [0, 1]
        0: today's 5-9 rot patches; 1: one to two patches, 40 % of the size, 35 % of the
        contrast. Patch count, size and darkness shrink linearly in between.
    one_sided_blemish : float, probability in [0, 1]
        Chance that a blemished onion's patches all lie on one third of its circumference.
    lighting_gain : float, [0, 0.5]
        Standard deviation of the per-session log brightness gain (0.2: about +-20 %); the
        per-channel colour cast has a third of it.
    lighting_drift : float, [0, 0.5]
        Relative amplitude of a slow sinusoidal drift of the gain (period 60-180 s).
    read_noise : float, 8-bit grey levels in [0, 30]
        Standard deviation of Gaussian sensor noise.
    shot_noise : float, [0, 3]
        Shot noise: standard deviation ``shot_noise * sqrt(value)`` in grey levels.
    motion_blur_px : float, pixels in [0, 20]
        Length of the linear blur kernel on main camera frames in motion (random direction per
        frame, length uniform in [0.5, 1] of this).
    jpeg_quality : int, 0 or [5, 95]
        Re-encode every colour image as JPEG at this quality; 0: no re-encoding.
    depth_noise_m : float, metres in [0, 0.05]
        Standard deviation of Gaussian depth noise (main camera).
    hand_cover : float, [0, 0.6]
        Largest share of the onion's box that the hand covers at inspection (each time
        uniform in [0.4, 1] of this).
    hand_cover_rate : float, probability in [0, 1]
        Chance that the hand covers the onion in an inspection view.
    partial_occlusion : float, probability in [0, 1]
        Chance that a passer-by walks past the edge of the view at a step without a full
        crossing.
    """

    name: str = "custom"
    blemish_subtlety: float = 0.0
    one_sided_blemish: float = 0.0
    lighting_gain: float = 0.0
    lighting_drift: float = 0.0
    read_noise: float = 0.0
    shot_noise: float = 0.0
    motion_blur_px: float = 0.0
    jpeg_quality: int = 0
    depth_noise_m: float = 0.0
    hand_cover: float = 0.0
    hand_cover_rate: float = 0.0
    partial_occlusion: float = 0.0

    def __post_init__(self) -> None:
        ranges = {"blemish_subtlety": (0, 1), "one_sided_blemish": (0, 1),
                  "lighting_gain": (0, 0.5), "lighting_drift": (0, 0.5), "read_noise": (0, 30),
                  "shot_noise": (0, 3), "motion_blur_px": (0, 20), "depth_noise_m": (0, 0.05),
                  "hand_cover": (0, 0.6), "hand_cover_rate": (0, 1),
                  "partial_occlusion": (0, 1)}
        for key, (low, high) in ranges.items():
            value = getattr(self, key)
            if not low <= value <= high:
                raise ValueError(f"{key} must be in [{low}, {high}]; got {value}")
        if self.jpeg_quality != 0 and not 5 <= self.jpeg_quality <= 95:
            raise ValueError(f"jpeg_quality must be 0 (off) or in [5, 95]; got "
                             f"{self.jpeg_quality}")

    @property
    def is_clean(self) -> bool:
        """Whether every knob is off (the world renders exactly as without a difficulty)."""
        return all(getattr(self, f.name) == 0 for f in fields(self) if f.name != "name")

    @property
    def image_effects(self) -> bool:
        """Whether any post-render image effect is on."""
        return any((self.lighting_gain, self.lighting_drift, self.read_noise, self.shot_noise,
                    self.motion_blur_px, self.jpeg_quality, self.depth_noise_m))

    def to_dict(self) -> dict:
        """A JSON-ready dict of the knobs."""
        return asdict(self)


DIFFICULTY_LEVELS: dict[str, Difficulty] = {
    "clean": Difficulty(name="clean"),
    "realistic": Difficulty(
        name="realistic", blemish_subtlety=0.4, one_sided_blemish=0.15, lighting_gain=0.1,
        lighting_drift=0.05, read_noise=2.5, shot_noise=0.3, motion_blur_px=4.0,
        jpeg_quality=80, depth_noise_m=0.004, hand_cover=0.3, hand_cover_rate=0.3,
        partial_occlusion=0.15),
    "paper": Difficulty(
        name="paper", blemish_subtlety=0.65, one_sided_blemish=0.3, lighting_gain=0.18,
        lighting_drift=0.1, read_noise=5.0, shot_noise=0.5, motion_blur_px=7.0,
        jpeg_quality=55, depth_noise_m=0.01, hand_cover=0.4, hand_cover_rate=0.5,
        partial_occlusion=0.25),
    "hard": Difficulty(
        name="hard", blemish_subtlety=0.85, one_sided_blemish=0.5, lighting_gain=0.25,
        lighting_drift=0.15, read_noise=9.0, shot_noise=0.8, motion_blur_px=10.0,
        jpeg_quality=35, depth_noise_m=0.02, hand_cover=0.5, hand_cover_rate=0.7,
        partial_occlusion=0.35),
}
"""The named levels, from today's clean world to a poor camera on a busy line."""


def resolve_difficulty(difficulty: Difficulty | str | dict) -> Difficulty:
    """A :class:`Difficulty` from itself, a level name, or a dict of knobs (``to_dict()``)."""
    if isinstance(difficulty, Difficulty):
        return difficulty
    if isinstance(difficulty, str):
        if difficulty not in DIFFICULTY_LEVELS:
            raise ValueError(f"unknown difficulty {difficulty!r}; the levels are "
                             f"{', '.join(DIFFICULTY_LEVELS)}")
        return DIFFICULTY_LEVELS[difficulty]
    if isinstance(difficulty, dict):
        return Difficulty(**difficulty)
    raise TypeError(f"difficulty must be a Difficulty, a level name or a dict; got "
                    f"{type(difficulty).__name__}")


def difficulty_rng(seed: int | np.random.SeedSequence, stream: int = 0) -> np.random.Generator:
    """The difficulty's generator for a session seeded with ``seed``: a stream of its own that
    does not advance (or spawn from) the session's seed sequence. ``stream`` > 0 gives further
    independent streams (one per camera, so that whether one camera renders never changes
    another's noise)."""
    return tagged_rng(seed, _TAG, stream)


def view_rng(seed: int | np.random.SeedSequence, onion: int, view: int
             ) -> np.random.Generator:
    """The difficulty's generator of one inspection view: view ``view`` of line-up onion
    ``onion`` at the station seeded with ``seed``. A stream of its own for every view, so that
    a view's noise (and the hand over it) depends on what the view is, never on what was
    rendered before it: whichever policy sorts the line-up, each onion looks the same."""
    for name, value in (("onion", onion), ("view", view)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
            raise ValueError(f"{name} must be an int >= 0; got {value!r}")
    seq = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    key = (*seq.spawn_key, _TAG, _VIEW_STREAM, int(onion), int(view))
    return np.random.default_rng(np.random.SeedSequence(seq.entropy, spawn_key=key))


#: the stream of :func:`view_rng` (after those of the station's cameras)
_VIEW_STREAM = 3


def tagged_rng(seed: int | np.random.SeedSequence, tag: int, stream: int = 0
               ) -> np.random.Generator:
    """A generator of its own for the session seeded with ``seed``, named by ``tag`` (one per
    kind of draw: the difficulty's, the look's), that does not advance (or spawn from) the
    session's seed sequence; ``stream`` > 0 gives further independent streams."""
    seq = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    key = (*seq.spawn_key, tag) + ((stream,) if stream else ())
    return np.random.default_rng(np.random.SeedSequence(seq.entropy, spawn_key=key))


class ImageEffects:
    """The post-render effects of one session (or station run), drawn from ``rng``.

    The per-session gain, colour cast and drift phase are drawn at construction; the noise,
    blur direction and hand patches at each call. With no image effect on, every call returns
    its input unchanged and draws nothing.
    """

    def __init__(self, difficulty: Difficulty, rng: np.random.Generator) -> None:
        self.difficulty, self.rng = difficulty, rng
        d = difficulty
        self.gain = np.ones(3)
        self.drift_period_s, self.drift_phase = 120.0, 0.0
        if d.lighting_gain or d.lighting_drift:
            cast = rng.normal(0.0, d.lighting_gain / 3, 3)
            self.gain = np.exp(rng.normal(0.0, d.lighting_gain) + cast)
            self.drift_period_s = float(rng.uniform(60.0, 180.0))
            self.drift_phase = float(rng.uniform(0.0, 2 * np.pi))

    def with_rng(self, rng: np.random.Generator) -> ImageEffects:
        """The same session's effects (gain, colour cast, drift) drawing their per-call noise
        from ``rng``: for a second camera of the same scene."""
        other = copy.copy(self)
        other.rng = rng
        return other

    def gain_at(self, time_s: float) -> np.ndarray:
        """Per-channel gain (3,) at ``time_s`` seconds into the session."""
        drift = self.difficulty.lighting_drift * np.sin(
            2 * np.pi * time_s / self.drift_period_s + self.drift_phase)
        return self.gain * (1.0 + drift)

    def color(self, rgb: np.ndarray, time_s: float = 0.0, moving: bool = False) -> np.ndarray:
        """``rgb`` (H, W, 3) uint8 as the real camera would deliver it, at ``time_s``."""
        d = self.difficulty
        if not d.image_effects:
            return rgb
        import cv2

        img = rgb.astype(np.float32)
        if d.lighting_gain or d.lighting_drift:
            img = img * self.gain_at(time_s).astype(np.float32)
        if moving and d.motion_blur_px >= 1.0:
            length = d.motion_blur_px * self.rng.uniform(0.5, 1.0)
            img = cv2.filter2D(img, -1, _line_kernel(length, self.rng.uniform(0, np.pi)),
                               borderType=cv2.BORDER_REFLECT)
        if d.read_noise or d.shot_noise:
            std = np.sqrt(d.read_noise**2 + d.shot_noise**2 * np.clip(img, 0, 255))
            img = img + std * self.rng.standard_normal(img.shape).astype(np.float32)
        out = np.clip(np.rint(img), 0, 255).astype(np.uint8)
        if d.jpeg_quality:
            ok, buf = cv2.imencode(".jpg", np.ascontiguousarray(out[..., ::-1]),
                                   [cv2.IMWRITE_JPEG_QUALITY, int(d.jpeg_quality)])
            if not ok:
                raise RuntimeError("JPEG encoding failed")
            out = np.ascontiguousarray(cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1])
        return out

    def depth(self, depth: np.ndarray) -> np.ndarray:
        """``depth`` (H, W) float32 metres with the sensor's noise."""
        if not self.difficulty.depth_noise_m:
            return depth
        noise = self.rng.normal(0.0, self.difficulty.depth_noise_m, depth.shape)
        return np.maximum(depth + noise.astype(np.float32), 0.0).astype(np.float32)

    def hand(self, rgb: np.ndarray, box, color) -> np.ndarray:
        """The inspection view ``rgb`` with the hand over the onion in ``box``, by chance."""
        return self.hand_and_cover(rgb, box, color)[0]

    def hand_and_cover(self, rgb: np.ndarray, box, color
                       ) -> tuple[np.ndarray, np.ndarray | None]:
        """:meth:`hand`, and the pixels (H, W) bool the hand covers (None if it covers
        none): what the labels of a view's visible blemishes leave out."""
        d = self.difficulty
        if box is None or not d.hand_cover or self.rng.random() >= d.hand_cover_rate:
            return rgb, None
        share = d.hand_cover * self.rng.uniform(0.4, 1.0)
        angle = self.rng.uniform(0, 2 * np.pi)
        return (hand_patch(rgb, box, share, angle, color),
                hand_patch(np.zeros(rgb.shape[:2], np.uint8), box, share, angle, 255) > 0)


def _line_kernel(length: float, angle: float) -> np.ndarray:
    """A normalised linear motion-blur kernel ``length`` pixels long at ``angle`` radians."""
    import cv2

    size = int(np.ceil(length)) | 1
    kernel = np.zeros((size, size), np.float32)
    c, half = size // 2, (length - 1) / 2
    dx, dy = half * np.cos(angle), half * np.sin(angle)
    cv2.line(kernel, (round(c - dx), round(c - dy)),
             (round(c + dx), round(c + dy)), 1.0, 1, cv2.LINE_AA)
    return kernel / kernel.sum()


def hand_patch(rgb: np.ndarray, box, share: float, angle: float, color) -> np.ndarray:
    """A copy of ``rgb`` with a filled ellipse of ``color`` (RGB, 0-255) over about ``share``
    of ``box`` (x_min, y_min, x_max, y_max), entering from the side at ``angle`` radians."""
    import cv2

    x0, y0, x1, y1 = (float(v) for v in box)
    w, h = max(x1 - x0, 1.0), max(y1 - y0, 1.0)
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    # an ellipse centred on the box's edge covers about half its own area inside the box
    scale = np.sqrt(2 * share / np.pi)
    ax, ay = max(1, round(w * scale)), max(1, round(h * scale))
    ex, ey = cx + 0.5 * w * np.cos(angle), cy + 0.5 * h * np.sin(angle)
    out = np.ascontiguousarray(rgb.copy())
    shade = [float(v) for v in np.clip(np.asarray(color, float).reshape(-1), 0, 255)]
    cv2.ellipse(out, (round(ex), round(ey)), (ax, ay), float(np.degrees(angle)),
                0, 360, shade, -1, cv2.LINE_AA)
    return out
