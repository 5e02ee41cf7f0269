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


def test_a_turned_flange_is_solved_from_its_wrist_turned_within_the_joint_limits(world):
    from robot.sawyer import Sawyer, flange_down, orientation_angle

    arm = Sawyer(world, base_position=(0.0, 0.0, 0.3))
    target = np.array([0.55, 0.1, 0.45])
    q = arm.solve(target)
    near = q.copy()
    near[6] = arm.upper[6] - 0.3  # a half turn the short way would cross the limit
    seeds = arm.wrist_turns(near, np.pi)
    turns = seeds[:, 6] - near[6]
    assert np.all((seeds[:, 6] >= arm.lower[6]) & (seeds[:, 6] <= arm.upper[6]))
    assert np.allclose(np.mod(turns - np.pi, 2 * np.pi), 0.0) and turns[0] == -np.pi
    assert np.all(np.diff(np.abs(turns)) >= 0) and np.array_equal(seeds[:, :6], np.repeat(
        near[None, :6], len(seeds), axis=0))
    centred = q.copy()
    centred[6] = 0.0  # two turns by 2 rad are within the limits: +2, then 2 - 2 pi
    np.testing.assert_allclose(arm.wrist_turns(centred, 2.0)[:, 6], [2.0, 2.0 - 2 * np.pi])
    arm.reset(near)
    _, start = arm.end_effector()
    turned = np.array(p.multiplyTransforms([0, 0, 0], start, [0, 0, 0],
                                           p.getQuaternionFromEuler([0, 0, np.pi]))[1])
    arm.reset(arm.solve(arm.end_effector()[0], turned, seeds))
    assert orientation_angle(arm.end_effector()[1], turned) < 0.01
    assert orientation_angle(flange_down(0.0), flange_down(np.pi)) == pytest.approx(np.pi)
