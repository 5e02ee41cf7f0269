"""The Sawyer station's cameras as a log and the inspection classifier see them.

The main camera watches the cell; the inspection camera (:data:`ROBOT_INSPECTION_CAMERA`) the
spot where the Sawyer holds an onion up. Both render under the station's lighting, through its
look's camera response (:mod:`robot.look`) and with the difficulty's image effects
(:mod:`robot.difficulty`) at the station's clock; the inspection view may also show the gripper
over part of the held onion. The main camera draws its noise from a stream of its own, and each
inspection view from one of its own (:func:`robot.difficulty.view_rng`). Image layouts as in
:mod:`robot.camera`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import NamedTuple

import numpy as np

from robot.belt import LineUpOnion
from robot.blemishes import BlemishProbe
from robot.camera import CameraImage, CameraSpec, Lighting, boxes_from_segmentation, render
from robot.difficulty import Difficulty, ImageEffects, difficulty_rng, view_rng
from robot.look import Look

__all__ = ["ROBOT_INSPECTION_CAMERA", "InspectionLabel", "StationCameras"]

_GRIPPER_RGB = (72.0, 72.0, 78.0)  # the suction gripper's grey, drawn over a held onion

ROBOT_INSPECTION_CAMERA = CameraSpec(
    width=320, height=240, fov_deg=38.0, eye=(0.02, 0.08, 1.50), target=(0.02, 0.32, 1.45),
    frame_id="inspection",
)
"""The Sawyer's inspection camera: the sorter's inspection spot (:data:`INSPECTION_CAMERA`'s
pose) at twice its resolution, 320x240 over a 38-degree field of view, so that a held onion
(6.4-9 cm across, 18 cm away) fills about 200 pixels of it instead of 50."""


class InspectionLabel(NamedTuple):
    """The ground truth of one onion in an inspection view: its box ``(x_min, y_min, x_max,
    y_max)`` (exclusive max), its class, its visible pixels, and how many of them show rot
    (None where not measured)."""

    box: tuple[int, int, int, int]
    blemished: bool
    visible_pixels: int
    rot_pixels: int | None = None


class StationCameras:
    """The station's main and inspection cameras in physics client ``client``.

    Parameters
    ----------
    client : int
        PyBullet physics client id.
    camera, inspection : CameraSpec
        The main camera and the inspection camera.
    lighting : Lighting
    look : Look or None
        The station's drawn look, whose camera response every image goes through.
    difficulty : Difficulty
    seed : numpy.random.SeedSequence
        The station's seed: the image effects draw from streams of their own
        (:func:`robot.difficulty.difficulty_rng`), which advance nothing else.
    cull : tuple of int
        Bodies the inspection camera leaves out (the arm, which never shows in its view).
    probe : BlemishProbe, optional
        Measures the rot each inspection view shows, for :meth:`inspection_labels`.

    Attributes
    ----------
    time_s : float
        The station's clock (s); the difficulty's lighting drift follows it.
    effects, inspection_effects : ImageEffects
        The image effects of the main camera and of the inspection camera.
    """

    def __init__(self, client: int, camera: CameraSpec, inspection: CameraSpec,
                 lighting: Lighting, look: Look | None, difficulty: Difficulty,
                 seed: np.random.SeedSequence, *, cull: tuple[int, ...] = (),
                 probe: BlemishProbe | None = None) -> None:
        self.client, self.camera, self.inspection = client, camera, inspection
        self.lighting, self.look, self.difficulty = lighting, look, difficulty
        self.cull, self.probe = cull, probe
        self.effects = ImageEffects(difficulty, difficulty_rng(seed))
        # the inspection camera's noise is a stream of its own (and a named view's, one of its
        # own): whether the main camera renders (a Rerun log, a Gymnasium observation) never
        # changes what the detector sees
        self.seed = seed
        self.inspection_effects = self.effects.with_rng(difficulty_rng(seed, 1))
        # and so has the view before the first action, rendered only for a recording of it
        self._initial_effects = self.effects.with_rng(difficulty_rng(seed, 2))
        self.time_s = 0.0

    def render(self, *, initial: bool = False) -> CameraImage:
        """The main camera's view now (with the difficulty's image effects).

        ``initial`` draws the effects' noise from a stream of its own, for the view before the
        first action: rendering it (to record the run from its start) never changes the
        renders after the actions.
        """
        image = render(self.client, self.camera, self.lighting)
        if self.look is not None:
            image = replace(image, rgb=self.look.camera(image.rgb))
        if self.difficulty.is_clean:
            return image
        effects = self._initial_effects if initial else self.effects
        return CameraImage(rgb=effects.color(image.rgb, self.time_s),
                           depth=effects.depth(image.depth), seg=image.seg)

    def render_inspection(self, held: int | None, *, view: tuple[int, int] | None = None,
                          time_s: float | None = None) -> CameraImage:
        """The inspection view now, as the classifier reads it: with the difficulty's image
        effects and, by chance, the gripper over part of the onion ``held`` (its body; None
        where the Sawyer holds none up).

        ``view`` ``(onion, k)`` names the view (the ``k``-th of line-up onion ``onion``): its
        noise and the gripper then come from the view's own stream
        (:func:`robot.difficulty.view_rng`), else from the inspection camera's. ``time_s``
        is the clock its light drifts to (the station's by default).
        """
        image = render(self.client, self.inspection, self.lighting, cull=self.cull)
        if self.look is not None:
            image = replace(image, rgb=self.look.camera(image.rgb))
        if self.difficulty.is_clean:
            return image
        box = None
        if held is not None:
            boxes = boxes_from_segmentation(image.seg, [held])
            box = next(iter(boxes.values()))[:4] if boxes else None
        effects = self.inspection_effects if view is None else \
            self.effects.with_rng(view_rng(self.seed, *view))
        rgb, covered = effects.hand_and_cover(image.rgb, box, _GRIPPER_RGB)
        return CameraImage(rgb=effects.color(rgb, self.time_s if time_s is None else time_s),
                           depth=image.depth, seg=image.seg, covered=covered)

    def inspection_labels(self, image: CameraImage, onions: Sequence[LineUpOnion]
                          ) -> list[InspectionLabel]:
        """The ground truth of each of ``onions`` in the inspection view ``image``, for training
        perception on what the robot will see.

        Boxes are ``(x_min, y_min, x_max, y_max)`` pixels (exclusive max) from the
        segmentation. With a ``probe`` each label counts the onion's pixels that show rot
        (:class:`robot.blemishes.BlemishProbe`, measured now: call it with the world as it
        was when ``image`` was rendered), leaving out those the gripper covers.
        """
        boxes = boxes_from_segmentation(image.seg, [o.body for o in onions])
        by_body = {o.body: o for o in onions}
        rot = ({} if self.probe is None else
               self.probe.rot_pixels(self.inspection, boxes, image.covered))
        return [InspectionLabel(tuple(b[:4]), by_body[body].appearance.blemished, b[4],
                                rot.get(body)) for body, b in boxes.items()]
