"""The human sorter: a torso, head and a two-bone right arm with a hand, built from primitives.

The arm is posed by analytic two-bone inverse kinematics (:func:`two_bone_ik`) from the shoulder
to a hand target; hand paths between locations are minimum-jerk (:func:`min_jerk`). Positions
have shape (3,) in world metres.
"""

from __future__ import annotations

import numpy as np
import pybullet as p

from robot.state_map import FACE_CENTER, SHOULDER

__all__ = ["HumanSorter", "min_jerk", "path_point", "two_bone_ik"]

UPPER_ARM = 0.38
FOREARM = 0.36
HAND_RADIUS = 0.04


def min_jerk(s: float | np.ndarray) -> float | np.ndarray:
    """The minimum-jerk time scaling ``10 s^3 - 15 s^4 + 6 s^5`` of ``s`` in [0, 1]."""
    s = np.clip(s, 0.0, 1.0)
    return 10 * s**3 - 15 * s**4 + 6 * s**5


def path_point(waypoints: np.ndarray, phase: float) -> np.ndarray:
    """Hand position at ``phase`` in [0, 1] along waypoints (K, 3), min-jerk per segment."""
    waypoints = np.asarray(waypoints, float)
    if waypoints.ndim != 2 or waypoints.shape[1] != 3 or len(waypoints) < 1:
        raise ValueError(f"waypoints must have shape (K, 3), K >= 1; got {waypoints.shape}")
    if len(waypoints) == 1:
        return waypoints[0].copy()
    n_seg = len(waypoints) - 1
    x = float(np.clip(phase, 0.0, 1.0)) * n_seg
    i = min(int(x), n_seg - 1)
    s = float(min_jerk(x - i))
    return waypoints[i] + s * (waypoints[i + 1] - waypoints[i])


def two_bone_ik(
    shoulder: np.ndarray, target: np.ndarray, upper: float, lower: float, pole: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Elbow and reached hand position of a two-bone arm pointing at ``target``.

    The elbow bends towards ``pole`` (a direction, (3,)). An unreachable target is approached
    along the shoulder-target line as far as the arm reaches.

    Returns
    -------
    elbow, hand : ndarray of shape (3,)
    """
    shoulder, target, pole = (np.asarray(x, float) for x in (shoulder, target, pole))
    offset = target - shoulder
    dist = float(np.linalg.norm(offset))
    direction = offset / dist if dist > 1e-9 else np.array([0.0, 0.0, -1.0])
    d = float(np.clip(dist, abs(upper - lower) + 1e-6, upper + lower - 1e-6))
    along = (upper**2 - lower**2 + d**2) / (2 * d)
    height = np.sqrt(max(upper**2 - along**2, 0.0))
    perp = pole - np.dot(pole, direction) * direction
    norm = np.linalg.norm(perp)
    perp = perp / norm if norm > 1e-9 else np.cross(direction, [1.0, 0.0, 0.0])
    perp = perp / np.linalg.norm(perp)
    elbow = shoulder + along * direction + height * perp
    return elbow, shoulder + d * direction


def _quat_z_to(v: np.ndarray) -> list[float]:
    """Quaternion (x, y, z, w) rotating the +z axis onto direction ``v``."""
    v = np.asarray(v, float) / np.linalg.norm(v)
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, v)
    s = np.linalg.norm(axis)
    if s < 1e-9:
        return [0.0, 0.0, 0.0, 1.0] if v[2] > 0 else [1.0, 0.0, 0.0, 0.0]
    angle = np.arctan2(s, np.dot(z, v))
    axis = axis / s * np.sin(angle / 2)
    return [*axis.tolist(), float(np.cos(angle / 2))]


def _body(client: int, shape: int, rgba, position, **kwargs) -> int:
    vis = p.createVisualShape(shape, rgbaColor=rgba, physicsClientId=client, **kwargs)
    return p.createMultiBody(
        0, -1, vis, basePosition=list(position), physicsClientId=client
    )


class HumanSorter:
    """The avatar in a physics client; :meth:`set_hand` poses the arm for a hand position.

    Parameters
    ----------
    client : int
        PyBullet physics client id.
    rng : numpy.random.Generator
        Draws the sorter's skin and clothing colours.
    """

    def __init__(self, client: int, rng: np.random.Generator) -> None:
        self.client = client
        skin = [*rng.uniform([0.45, 0.3, 0.2], [0.95, 0.75, 0.6]).tolist(), 1.0]
        shirt = [*rng.uniform(0.1, 0.8, 3).tolist(), 1.0]
        torso_center = np.array([0.0, 0.55, 1.12])
        self.torso = _body(
            client, p.GEOM_BOX, shirt, torso_center, halfExtents=[0.2, 0.1, 0.3]
        )
        self.legs = _body(
            client, p.GEOM_BOX, [0.15, 0.15, 0.25, 1.0], [0.0, 0.55, 0.41],
            halfExtents=[0.16, 0.09, 0.41],
        )
        self.head = _body(client, p.GEOM_SPHERE, skin, FACE_CENTER, radius=0.11)
        left_shoulder = SHOULDER * np.array([-1.0, 1.0, 1.0])
        self.left_arm = _body(
            client, p.GEOM_CAPSULE, shirt, left_shoulder - [0.02, 0.0, 0.33],
            radius=0.045, length=0.6,
        )
        self.upper_arm = _body(client, p.GEOM_CAPSULE, shirt, SHOULDER, radius=0.045,
                               length=UPPER_ARM)
        self.forearm = _body(client, p.GEOM_CAPSULE, skin, SHOULDER, radius=0.035,
                             length=FOREARM)
        self.hand = _body(client, p.GEOM_SPHERE, skin, SHOULDER, radius=HAND_RADIUS)
        self.skin = np.array(skin[:3]) * 255.0  # RGB in [0, 255], for drawn fingers
        self.body_ids = (self.torso, self.legs, self.head, self.left_arm, self.upper_arm,
                         self.forearm, self.hand)
        self.hand_position = SHOULDER - np.array([0.0, 0.0, UPPER_ARM + FOREARM])

    def set_hand(self, target: np.ndarray) -> np.ndarray:
        """Pose the arm so the hand reaches ``target`` (3,); returns the hand position (3,)."""
        pole = np.array([0.6, 0.3, -1.0])  # elbow out to the side and down
        elbow, hand = two_bone_ik(SHOULDER, target, UPPER_ARM, FOREARM, pole)
        for body, a, b in ((self.upper_arm, SHOULDER, elbow), (self.forearm, elbow, hand)):
            p.resetBasePositionAndOrientation(
                body, ((a + b) / 2).tolist(), _quat_z_to(b - a), physicsClientId=self.client
            )
        p.resetBasePositionAndOrientation(
            self.hand, hand.tolist(), [0, 0, 0, 1], physicsClientId=self.client
        )
        self.hand_position = hand
        return hand
