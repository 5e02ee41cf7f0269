"""Cameras: boxes and occlusion from the segmentation buffer, intrinsics, textures."""

from __future__ import annotations

import numpy as np
import pybullet as p
import pytest

from robot.camera import (
    CameraSpec,
    boxes_from_segmentation,
    intrinsics,
    occluded_fraction,
    render,
)
from robot.onions import onion_texture, sample_appearance
from robot.scene import connect


def test_boxes_from_segmentation_on_a_hand_made_mask():
    seg = -np.ones((6, 8), np.int32)
    seg[1:3, 2:5] = 7
    seg[4, 0] = 9
    boxes = boxes_from_segmentation(seg, [7, 9, 11])
    assert boxes == {7: (2, 1, 5, 3, 6), 9: (0, 4, 1, 5, 1)}
    assert occluded_fraction(seg, [7]) == pytest.approx(6 / 48)


def test_camera_spec_validates():
    with pytest.raises(ValueError, match="near < far"):
        CameraSpec(near=2.0, far=1.0)
    with pytest.raises(ValueError, match="width and height"):
        CameraSpec(width=4)


def test_rendered_box_surrounds_the_projection_of_a_sphere():
    client = connect()
    try:
        spec = CameraSpec(width=160, height=120, eye=(0.0, -1.0, 1.0), target=(0.0, 0.0, 1.0))
        vis = p.createVisualShape(p.GEOM_SPHERE, radius=0.05, physicsClientId=client)
        center = np.array([0.1, 0.0, 1.05])
        body = p.createMultiBody(0, -1, vis, center.tolist(), physicsClientId=client)
        image = render(client, spec)
        assert image.rgb.shape == (120, 160, 3) and image.depth.shape == (120, 160)
        box = boxes_from_segmentation(image.seg, [body])[body]
        # camera looks along +y: u grows with x, v grows with -z
        K = intrinsics(spec)
        u = K[0, 2] + K[0, 0] * (center[0] - 0.0) / 1.0
        v = K[1, 2] - K[1, 1] * (center[2] - 1.0) / 1.0
        assert box[0] < u < box[2] and box[1] < v < box[3]
        r_px = K[0, 0] * 0.05 / 1.0
        assert box[2] - box[0] == pytest.approx(2 * r_px, abs=3)
        v_i, u_i = round(v), round(u)
        assert image.depth[v_i, u_i] == pytest.approx(0.95, abs=0.01)
    finally:
        p.disconnect(physicsClientId=client)


def test_blemished_onions_carry_dark_patches():
    rng = np.random.default_rng(0)
    def dark(blemished):
        tex = onion_texture(sample_appearance(rng, blemished), 64).astype(float)
        return (tex.mean(-1) < 60).mean()
    good = np.mean([dark(False) for _ in range(10)])
    bad = np.mean([dark(True) for _ in range(10)])
    assert bad > good + 0.05
    with pytest.raises(ValueError, match="size must be"):
        onion_texture(sample_appearance(rng, True), 8)
