"""Which pixels of a view show rot: ground truth for the inspection classifier.

A blemished onion hides its rot from a view where the patches face away, lie under the gripper
or the hand, or are too small to see. Telling the inspection classifier "blemished" on such a
view teaches it to see rot where there is none; :class:`BlemishProbe` measures instead how many
of a view's pixels show rot. For each onion it loads, beside the onion's texture, a second one
painted with its :func:`robot.onions.blemish_mask` (white rot on black); to measure a view it
swaps the mask in, renders the same camera under flat white light (each texel's colour is its
mask value), counts the onion's pixels that come out white and not under the hand, and swaps the
texture back. Rendering the mask changes nothing the cameras see.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pybullet as p

from robot.camera import CameraSpec, Lighting, render
from robot.onions import OnionAppearance, blemish_mask, save_texture

__all__ = ["FLAT_LIGHT", "BlemishProbe"]

FLAT_LIGHT = Lighting(direction=(0.0, 0.0, 1.0), color=(1.0, 1.0, 1.0), ambient=1.0,
                      diffuse=0.0, specular=0.0)
"""Light under which a rendered texel keeps its texture's colour."""


class BlemishProbe:
    """Measures the rot each onion shows in a view (see the module docstring).

    Parameters
    ----------
    client : int
        The physics client holding the onions.
    """

    def __init__(self, client: int) -> None:
        self.client = client
        self._textures: dict[int, tuple[int, int]] = {}  # body -> (texture, mask texture)

    def add(self, body: int, texture: int, appearance: OnionAppearance, size: int, *,
            subtlety: float = 0.0, one_sided: float = 0.0) -> None:
        """Register onion ``body``, textured with ``texture`` (a PyBullet texture id) made by
        :func:`robot.onions.onion_texture` from ``appearance`` with the same arguments."""
        mask = blemish_mask(appearance, size, subtlety=subtlety, one_sided=one_sided)
        image = np.repeat((mask * 255).astype(np.uint8)[..., None], 3, axis=2)
        with tempfile.TemporaryDirectory(prefix="blemish-mask-") as tmp:
            png = save_texture(image, Path(tmp) / "mask.png")
            mask_id = p.loadTexture(str(png), physicsClientId=self.client)
        self._textures[int(body)] = (int(texture), int(mask_id))

    def rot_pixels(self, spec: CameraSpec, bodies, covered: np.ndarray | None = None
                   ) -> dict[int, int]:
        """``body -> number of its pixels in ``spec``'s view that show rot`` for each of
        ``bodies`` registered here; ``covered`` (H, W) bool marks pixels the hand hides."""
        bodies = [int(b) for b in bodies if int(b) in self._textures]
        if not bodies:
            return {}
        try:
            for b in bodies:
                p.changeVisualShape(b, -1, textureUniqueId=self._textures[b][1],
                                    physicsClientId=self.client)
            image = render(self.client, spec, FLAT_LIGHT)
        finally:
            for b in bodies:
                p.changeVisualShape(b, -1, textureUniqueId=self._textures[b][0],
                                    physicsClientId=self.client)
        rot = image.rgb.max(axis=2) >= 128
        if covered is not None:
            rot &= ~covered
        return {b: int(np.count_nonzero(rot & (image.seg == b))) for b in bodies}
