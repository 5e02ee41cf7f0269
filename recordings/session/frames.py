"""What the recordings need of a simulator's frames, stated as protocols.

The simulator (``robot/``) produces frames with their ground truth; the session and dataset
writers consume them. Neither package imports the other: the writers state here what they read,
and the simulator's dataclasses (``robot.labels``) satisfy these protocols structurally. The
stage that records a session is the only place that knows both. A frame's step is the one type
both share, :class:`irl.demonstrations.StepTruth`.

Layouts: ``color[v, u, c]`` (H, W, 3) uint8 RGB, ``depth[v, u]`` (H, W) float metres.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from irl.demonstrations import StepTruth

__all__ = ["TrueOnion", "TruthFrame"]


class TrueOnion(Protocol):
    """One onion in one frame: class, world position, and its box where visible."""

    @property
    def onion_id(self) -> int: ...
    @property
    def blemished(self) -> bool: ...
    @property
    def position(self) -> np.ndarray: ...
    @property
    def in_focus(self) -> bool: ...
    @property
    def box(self) -> tuple[int, int, int, int] | None: ...
    @property
    def visible_pixels(self) -> int: ...


class TruthFrame(Protocol):
    """A rendered frame with its ground truth (``robot.labels.Frame`` satisfies it).

    ``phase`` is the frame's position in its step; ``inspection`` is the inspection view on a
    step's first frame (else None) and ``inspection_onions`` the onions seen in it.
    """

    @property
    def index(self) -> int: ...
    @property
    def step(self) -> StepTruth: ...
    @property
    def phase(self) -> int: ...
    @property
    def time_s(self) -> float: ...
    @property
    def color(self) -> np.ndarray: ...
    @property
    def depth(self) -> np.ndarray: ...
    @property
    def onions(self) -> tuple[TrueOnion, ...]: ...
    @property
    def occluded_fraction(self) -> float: ...
    @property
    def inspection(self) -> np.ndarray | None: ...
    @property
    def inspection_onions(self) -> tuple[TrueOnion, ...]: ...
