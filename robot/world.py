"""Snapshots of the PyBullet world for 3D logging: bodies as primitives, cameras, the robot.

A :class:`WorldState` is what a session's 3D topics are written from (``/tf``, ``/joint_states``,
``/scene``; see ``recordings.session.world``): every body of the work cell as a simple shape in the
world, the pose of each camera's optical frame, and the robot's joint positions where there is
a robot. Taking one only reads the physics client (poses and visual shapes), so it changes
nothing that is rendered or drawn from a random stream.

Conventions: positions are world metres, shape (3,); orientations are unit quaternions
``(x, y, z, w)``, shape (4,); the world is z-up. A camera's optical frame has x right, y down and
z forward (ROS ``*_optical_frame``, Rerun's ``RDF``), so that a point ``X`` in it projects to
pixel ``K @ X / X[2]``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pybullet as p

from robot.camera import CameraSpec
from robot.labels import Frame

__all__ = [
    "Pose",
    "RobotState",
    "ShapeState",
    "WorldFrame",
    "WorldProbe",
    "WorldState",
    "camera_pose",
    "robot_state",
]

#: PyBullet geometry types and the names of the shapes they become.
_KINDS = {p.GEOM_BOX: "box", p.GEOM_SPHERE: "sphere", p.GEOM_CAPSULE: "capsule",
          p.GEOM_CYLINDER: "cylinder"}


@dataclass(frozen=True)
class Pose:
    """A rigid transform: ``position`` (3,) and ``orientation`` (4,) quaternion ``(x, y, z, w)``
    of a child frame in its parent."""

    position: np.ndarray
    orientation: np.ndarray

    def __post_init__(self) -> None:
        pos = np.asarray(self.position, float).reshape(-1)
        quat = np.asarray(self.orientation, float).reshape(-1)
        if pos.shape != (3,) or quat.shape != (4,):
            raise ValueError(f"a pose needs position (3,) and orientation (4,); got shapes "
                             f"{pos.shape} and {quat.shape}")
        norm = float(np.linalg.norm(quat))
        if not np.isfinite(norm) or norm < 1e-9:
            raise ValueError(f"orientation must be a non-zero quaternion (x, y, z, w); got {quat}")
        object.__setattr__(self, "position", pos)
        object.__setattr__(self, "orientation", quat / norm)


@dataclass(frozen=True)
class ShapeState:
    """One body of the world as a primitive, where it is now.

    Attributes
    ----------
    name : str
        ``group/part`` (``workcell/belt``, ``sorter/hand``, ``onions/3``) or a bare group
        (``gate``); unique in a snapshot and stable over a session.
    kind : {"box", "sphere", "cylinder", "capsule"}
    size : ndarray of shape (3,)
        Box: full extents along its x, y, z. Sphere: diameters ``(d, d, d)``. Cylinder and
        capsule (along their z): ``(2 r, 2 r, length)``, a capsule's length without its caps.
    rgba : ndarray of shape (4,)
        Colour in [0, 1].
    pose : Pose
        The shape's centre and orientation in the world.
    class_id : int or None
        An onion's true class (0 good, 1 blemished); None for every other body.
    """

    name: str
    kind: str
    size: np.ndarray
    rgba: np.ndarray
    pose: Pose
    class_id: int | None = None


@dataclass(frozen=True)
class RobotState:
    """A robot arm at one instant: its model, where its base stands, its joint positions.

    Attributes
    ----------
    name : str
    urdf : Path
        The robot's URDF (its link and joint names are the frames of ``/tf``).
    base : Pose
        The URDF root link's frame in the world.
    joint_names : tuple of str
        The actuated joints, in the order of ``positions``.
    positions : ndarray of shape (n_joints,)
        Joint positions (radians for revolute joints).
    """

    name: str
    urdf: Path
    base: Pose
    joint_names: tuple[str, ...]
    positions: np.ndarray

    def __post_init__(self) -> None:
        q = np.asarray(self.positions, float).reshape(-1)
        if q.shape != (len(self.joint_names),):
            raise ValueError(f"positions must hold one value per joint {self.joint_names}; got "
                             f"shape {q.shape}")
        object.__setattr__(self, "positions", q)


@dataclass(frozen=True)
class WorldState:
    """Everything of the world that is drawn in 3D, at one instant.

    ``cameras`` maps a camera's ``frame_id`` (``camera``, ``inspection``) to its optical frame's
    pose in the world; ``robot`` is None in a world without one (a human sorter's session).
    """

    shapes: tuple[ShapeState, ...]
    cameras: Mapping[str, Pose]
    robot: RobotState | None = None


@dataclass(frozen=True)
class WorldFrame(Frame):
    """A rendered frame with its ground truth and a snapshot of the world it shows."""

    world: WorldState | None = field(default=None, repr=False)


def _quat_from_matrix(R: np.ndarray) -> np.ndarray:
    """The unit quaternion (x, y, z, w) of rotation matrix ``R`` (3, 3)."""
    R = np.asarray(R, float)
    w = np.sqrt(max(0.0, 1.0 + R[0, 0] + R[1, 1] + R[2, 2])) / 2
    x = np.sqrt(max(0.0, 1.0 + R[0, 0] - R[1, 1] - R[2, 2])) / 2
    y = np.sqrt(max(0.0, 1.0 - R[0, 0] + R[1, 1] - R[2, 2])) / 2
    z = np.sqrt(max(0.0, 1.0 - R[0, 0] - R[1, 1] + R[2, 2])) / 2
    x = np.copysign(x, R[2, 1] - R[1, 2])
    y = np.copysign(y, R[0, 2] - R[2, 0])
    z = np.copysign(z, R[1, 0] - R[0, 1])
    q = np.array([x, y, z, w])
    return q / np.linalg.norm(q)


def camera_pose(spec: CameraSpec) -> Pose:
    """The pose in the world of ``spec``'s optical frame (x right, y down, z forward)."""
    eye, target, up = (np.asarray(v, float) for v in (spec.eye, spec.target, spec.up))
    forward = target - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    if np.linalg.norm(right) < 1e-9:
        raise ValueError(f"camera {spec.frame_id!r}: up {spec.up} is parallel to the viewing "
                         "direction")
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    return Pose(eye, _quat_from_matrix(np.column_stack([right, down, forward])))


class WorldProbe:
    """Reads named bodies of a physics client as :class:`ShapeState`s.

    Parameters
    ----------
    client : int
        PyBullet physics client id.
    bodies : mapping of str to int
        Shape name -> body id of single-link bodies made of one primitive (box, sphere,
        cylinder, capsule); a body of another kind is left out.
    classes : mapping of str to int
        Shape name -> class id, for the bodies that have one (onions).
    """

    def __init__(self, client: int, bodies: Mapping[str, int],
                 classes: Mapping[str, int] | None = None) -> None:
        self.client = client
        self.bodies = dict(bodies)
        self.classes = dict(classes or {})
        self._geometry: dict[str, tuple[str, np.ndarray, np.ndarray, Pose]] = {}
        for name, body in self.bodies.items():
            data = p.getVisualShapeData(body, physicsClientId=client)
            if not data or data[0][2] not in _KINDS:
                continue
            _, _, geom, dims, _, local_pos, local_orn, rgba = data[0][:8]
            kind = _KINDS[geom]
            if kind == "box":
                size = np.asarray(dims, float)
            elif kind == "sphere":
                size = np.full(3, 2.0 * dims[0])
            else:  # cylinder, capsule: (length, radius)
                size = np.array([2.0 * dims[1], 2.0 * dims[1], dims[0]])
            self._geometry[name] = (kind, size, np.asarray(rgba, float),
                                    Pose(local_pos, local_orn))

    def shapes(self) -> tuple[ShapeState, ...]:
        """Every readable body where it is now, in the order of ``bodies``."""
        out = []
        for name, (kind, size, rgba, local) in self._geometry.items():
            pos, orn = p.getBasePositionAndOrientation(self.bodies[name],
                                                       physicsClientId=self.client)
            pos, orn = p.multiplyTransforms(pos, orn, local.position.tolist(),
                                            local.orientation.tolist())
            out.append(ShapeState(name=name, kind=kind, size=size.copy(), rgba=rgba.copy(),
                                  pose=Pose(pos, orn), class_id=self.classes.get(name)))
        return tuple(out)


def _base_link_pose(client: int, body: int) -> Pose:
    """The URDF root link's frame of ``body`` (PyBullet reports the base's inertial frame)."""
    com_pos, com_orn = p.getBasePositionAndOrientation(body, physicsClientId=client)
    local_pos, local_orn = p.getDynamicsInfo(body, -1, physicsClientId=client)[3:5]
    inv_pos, inv_orn = p.invertTransform(local_pos, local_orn)
    pos, orn = p.multiplyTransforms(com_pos, com_orn, inv_pos, inv_orn)
    return Pose(pos, orn)


def robot_state(client: int, body: int, joints: Sequence[int], urdf: Path,
                name: str = "sawyer") -> RobotState:
    """The robot ``body`` of ``client`` now: its base link's pose and the positions of its
    ``joints`` (PyBullet joint indices), named as in its ``urdf``."""
    names = tuple(p.getJointInfo(body, j, physicsClientId=client)[1].decode() for j in joints)
    q = np.array([s[0] for s in p.getJointStates(body, list(joints), physicsClientId=client)])
    return RobotState(name=name, urdf=Path(urdf), base=_base_link_pose(client, body),
                      joint_names=names, positions=q)
