"""The Sawyer loads from its official URDF, reaches targets by IK and holds by suction."""

from __future__ import annotations

import importlib.util

import numpy as np
import pybullet as p
import pytest

from robot import assets
from robot.scene import connect


@pytest.fixture
def world():
    client = connect()
    yield client
    p.disconnect(physicsClientId=client)


def test_missing_asset_package_names_the_install_command(monkeypatch):
    monkeypatch.setattr(importlib.util, "find_spec", lambda name: None)
    install = r"pip install --no-deps robosuite==1\.5\.2"
    with pytest.raises(assets.AssetNotFoundError, match=install):
        assets.sawyer_urdf()


def test_sawyer_loads_reaches_by_ik_and_grasps(world):
    from robot.sawyer import Sawyer

    floor = p.createCollisionShape(p.GEOM_BOX, halfExtents=[2, 2, 0.01], physicsClientId=world)
    p.createMultiBody(0, floor, -1, [0, 0, -0.01], physicsClientId=world)
    arm = Sawyer(world, base_position=(0.0, 0.0, 0.3))
    assert len(arm.joints) == 7
    target = np.array([0.6, 0.1, 0.4])
    q = arm.inverse_kinematics(target)
    assert np.all(q >= arm.lower) and np.all(q <= arm.upper)
    arm.reset(q)
    assert np.linalg.norm(arm.end_effector()[0] - target) < 1e-3

    ball = p.createMultiBody(0.1, p.createCollisionShape(p.GEOM_SPHERE, radius=0.04,
                                                         physicsClientId=world),
                             -1, [0.6, 0.1, 0.04], physicsClientId=world)
    assert arm.move_to([0.6, 0.1, 0.085]) < 0.01
    arm.grasp(ball)
    assert arm.move_to([0.4, -0.3, 0.6]) < 0.01
    held = np.array(p.getBasePositionAndOrientation(ball, physicsClientId=world)[0])
    assert held[2] > 0.45  # lifted with the flange
    arm.release()
    for _ in range(240):
        p.stepSimulation(physicsClientId=world)
    dropped = np.array(p.getBasePositionAndOrientation(ball, physicsClientId=world)[0])
    assert dropped[2] == pytest.approx(0.04, abs=0.01)
