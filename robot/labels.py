"""Ground-truth label types of a simulated session, shared by the simulator and the recordings.

Pure data (numpy only): ``recordings/`` writes and reads these without importing pybullet.
States and actions are flat indices of :mod:`irl.domains.onion_sorting`; a frame's step is an
:class:`irl.demonstrations.StepTruth`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from irl.demonstrations import StepTruth

__all__ = ["Frame", "OnionLabel"]


@dataclass(frozen=True)
class OnionLabel:
    """One onion in one frame.

    Attributes
    ----------
    onion_id : int
        Index of the onion in the session's pool (stable over the session).
    blemished : bool
        The onion's true class.
    position : ndarray of shape (3,)
        World position in metres.
    in_focus : bool
        Whether it is the onion of the MDP state.
    box : tuple of 4 int or None
        ``(x_min, y_min, x_max, y_max)`` of its visible pixels in the main camera (exclusive
        max), from the segmentation buffer; None when not visible.
    visible_pixels : int
        Number of its visible pixels.
    rot_pixels : int or None
        How many of them show rot, not hidden by a hand (:mod:`robot.blemishes`); None where
        not measured.
    """

    onion_id: int
    blemished: bool
    position: np.ndarray = field(repr=False)
    in_focus: bool = False
    box: tuple[int, int, int, int] | None = None
    visible_pixels: int = 0
    rot_pixels: int | None = None


@dataclass(frozen=True)
class Frame:
    """One rendered frame with its ground truth.

    Attributes
    ----------
    index : int
        Frame number in the session.
    step : StepTruth
        The abstract step this frame belongs to; the frame is labelled ``(step.state,
        step.action)``; ``step.occluded`` says whether the passer-by walked through the
        camera's view during the step. The step's first frame (``phase == 0``) shows
        ``step.state`` at rest.
    phase : int
        Position of the frame within its step, ``0 <= phase < frames_per_step``.
    time_s : float
        Simulated time in seconds.
    color : ndarray of shape (H, W, 3)
        uint8 RGB of the main camera.
    depth : ndarray of shape (H, W)
        float32 depth in metres.
    onions : tuple of OnionLabel
    occluded_fraction : float
        Fraction of the main view covered by the passer-by, in [0, 1].
    inspection : ndarray of shape (h, w, 3) or None
        uint8 RGB of the inspection view (rendered on the first frame of each step).
    inspection_onions : tuple of OnionLabel
        The onions visible in the inspection view, with their boxes in that view; empty when
        there is no inspection view.
    """

    index: int
    step: StepTruth
    phase: int
    time_s: float
    color: np.ndarray = field(repr=False)
    depth: np.ndarray = field(repr=False)
    onions: tuple[OnionLabel, ...] = ()
    occluded_fraction: float = 0.0
    inspection: np.ndarray | None = field(default=None, repr=False)
    inspection_onions: tuple[OnionLabel, ...] = ()
