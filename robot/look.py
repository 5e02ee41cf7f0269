"""Domain randomization of the world's look, for training data that spans cameras and rooms.

A model trained on one rendered look fails on another camera (``onionsort eval-perception
--camera-shift``). With ``randomize_look`` on, each session (and each station run) draws a
:class:`Look` of its own: the light's colour, intensity and direction; the colours of the
floor, the belt, its stand and rails, the bin and its stand; and the camera's exposure and
white balance. The onions are never recoloured (their colour is what tells a blemish) and the
stop gate keeps its colour (the state classifier reads it).

The look is drawn from a stream of its own (:func:`look_rng`, from the session's seed like the
difficulty's), so a session's states, actions, onions, crossings and difficulty effects are
the same with the look randomized or not; with it off nothing is drawn and the world renders
exactly as without this module. It is a knob beside the difficulty levels, never part of one:
a level is a fixed test of perception, and randomization is for the training data
(``onionsort dataset --randomize-look``).

Layouts: ``rgb`` (H, W, 3) uint8; gains (3,) per RGB channel in linear light.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pybullet as p

from robot.camera import Lighting
from robot.difficulty import tagged_rng

__all__ = ["SURFACES", "Look", "draw_look", "look_rng"]

#: spawn-key tag of the look's generator (kept apart from the session's and the difficulty's)
_TAG = 0x100C

SURFACES = ("floor", "belt", "stand", "rails", "bin", "bin_stand")
"""What a look recolours, each a group of the workcell's bodies (:func:`_groups`)."""

#: a power-law encoding: gains in linear light act on encoded values as gain ** (1 / 2.2)
_ENCODING_GAMMA = 2.2


@dataclass(frozen=True)
class Look:
    """One session's look.

    Attributes
    ----------
    lighting : Lighting
        The light: direction, colour and Phong coefficients (its intensity).
    surfaces : dict
        ``name -> (r, g, b)`` in [0, 1] for each of :data:`SURFACES`.
    gains : tuple of 3 floats
        The camera's exposure times its white balance, per channel, in linear light.
    """

    lighting: Lighting
    surfaces: dict
    gains: tuple[float, float, float]

    def camera(self, rgb: np.ndarray) -> np.ndarray:
        """``rgb`` (H, W, 3) uint8 through this look's camera (exposure, white balance): a
        new array."""
        g = np.asarray(self.gains, np.float32) ** np.float32(1 / _ENCODING_GAMMA)
        return np.clip(np.rint(rgb.astype(np.float32) * g), 0, 255).astype(np.uint8)

    def paint(self, client: int, workcell: dict[str, int]) -> None:
        """Recolour the workcell's bodies (``name -> body id``, :func:`robot.scene.
        build_workcell`) in ``client``."""
        for surface, names in _groups(workcell).items():
            rgba = [*self.surfaces[surface], 1.0]
            for name in names:
                p.changeVisualShape(workcell[name], -1, rgbaColor=rgba, physicsClientId=client)


def _groups(workcell: dict[str, int]) -> dict[str, list[str]]:
    """The workcell's body names by surface of :data:`SURFACES`."""
    groups: dict[str, list[str]] = {s: [] for s in SURFACES}
    for name in workcell:
        if name in ("floor", "belt", "bin_stand"):
            groups[name].append(name)
        elif name.startswith("stand_leg") or name == "pedestal":
            groups["stand"].append(name)
        elif name.startswith("rail"):
            groups["rails"].append(name)
        elif name.startswith("bin_"):
            groups["bin"].append(name)
    return groups


def look_rng(seed: int | np.random.SeedSequence, stream: int = 0) -> np.random.Generator:
    """The look's generator for a session seeded with ``seed``: a stream of its own that does
    not advance (or spawn from) the session's seed sequence."""
    return tagged_rng(seed, _TAG, stream)


def _tint(rng: np.random.Generator, warmth: float) -> np.ndarray:
    """A light's colour (3,) in [0, 1]: warm (> 0) to cool (< 0), a touch of green/magenta."""
    green = rng.uniform(-0.04, 0.04)
    color = np.array([1.0 + warmth, 1.0 + green, 1.0 - warmth])
    return np.clip(color / color.max(), 0.0, 1.0)


def draw_look(rng: np.random.Generator) -> Look:
    """A look drawn from ``rng`` (:func:`look_rng`).

    Light: direction over the upper hemisphere in front of the line, colour from warm (about
    3,000 K) to cool, intensity 0.6x-1.3x today's; surfaces: greys, browns and muted colours
    for the floor and stands, a belt from near black to mid grey with a tint, any hue for the
    bin; camera: exposure within +-0.7 stops, white balance off by up to about +-25% between
    red and blue.
    """
    direction = rng.uniform([-1.2, -1.2, 0.4], [1.2, 0.6, 1.6])
    intensity = rng.uniform(0.6, 1.3)
    lighting = Lighting(
        direction=tuple(direction.round(4).tolist()),
        color=tuple(_tint(rng, rng.uniform(-0.3, 0.25)).round(4).tolist()),
        ambient=float(np.clip(rng.uniform(0.4, 0.7) * intensity, 0.15, 0.95)),
        diffuse=float(np.clip(rng.uniform(0.2, 0.5) * intensity, 0.05, 0.8)),
        specular=float(rng.uniform(0.0, 0.15)),
    )

    def muted(low: float, high: float, tint: float) -> tuple[float, float, float]:
        base = rng.uniform(low, high)
        return tuple(float(v) for v in np.clip(base * (1 + rng.uniform(-tint, tint, 3)), 0, 1))

    hue = rng.uniform(0, 2 * np.pi)
    bin_rgb = 0.45 + 0.3 * np.cos(hue - np.array([0.0, 2.094, 4.189]))
    surfaces = {"floor": muted(0.2, 0.75, 0.25), "belt": muted(0.06, 0.4, 0.15),
                "stand": muted(0.3, 0.8, 0.1), "rails": muted(0.35, 0.8, 0.1),
                "bin": tuple(float(v) for v in np.clip(bin_rgb * rng.uniform(0.6, 1.1), 0, 1)),
                "bin_stand": muted(0.25, 0.7, 0.1)}
    exposure = 2.0 ** rng.uniform(-0.7, 0.7)
    balance = np.exp(rng.uniform(-0.12, 0.12))
    gains = exposure * np.array([balance, 1.0, 1.0 / balance])
    return Look(lighting=lighting, surfaces=surfaces, gains=tuple(float(g) for g in gains))
