"""The 3D side of a session: transforms, joint states and scene entities in Foxglove's schemas.

A simulator's frame may carry a snapshot of its world (:class:`World`: ``robot.world.WorldState``
satisfies it; this module does not import ``robot``). The session writer turns it into

==============  ========================  ===================================================
topic           schema                    content
==============  ========================  ===================================================
/tf             foxglove.FrameTransforms  ``world`` -> each camera's optical frame
                                          (``camera``, ``inspection``: the ``frame_id`` of the
                                          images and calibrations); with a robot, ``world`` ->
                                          its root link and each joint's parent -> child link
/joint_states   foxglove.JointStates      the robot's joint positions (with a robot)
/scene          foxglove.SceneUpdate      every body as a cube, sphere or cylinder in
                                          ``world``: belt, bin, gate, sorter, passer-by, and
                                          the onions in the colour of their true class
==============  ========================  ===================================================

and the reader reads them back (:func:`read_transforms`, :func:`read_joint_states`,
:func:`read_scene`). ``/tf`` and ``/joint_states`` belong to the sensor side (a work cell knows
where its cameras are and what its robot's joints read); ``/scene`` is ground truth.

Conventions: positions in metres (3,), quaternions ``(x, y, z, w)`` (4,), the world z-up; a
camera's optical frame has x right, y down, z forward.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.JointStates_pb2 import JointStates
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

from recordings.session.schema import CLASS_COLORS, CLASS_NAMES
from recordings.session.urdf import UrdfJoints

__all__ = [
    "WORLD_FRAME",
    "Pose",
    "Robot",
    "SceneItem",
    "Shape",
    "Transform",
    "World",
    "frame_transforms",
    "joint_states",
    "read_joint_states",
    "read_scene",
    "read_transforms",
    "robot_record",
    "scene_update",
]

#: The fixed frame every pose is given in.
WORLD_FRAME = "world"
_KINDS = ("box", "sphere", "cylinder", "capsule")


class Pose(Protocol):
    """A child frame in its parent: ``position`` (3,), ``orientation`` (4,) ``(x, y, z, w)``."""

    @property
    def position(self) -> np.ndarray: ...
    @property
    def orientation(self) -> np.ndarray: ...


class Shape(Protocol):
    """A body as a primitive (``robot.world.ShapeState``): ``name`` (``group/part``), ``kind``
    (box, sphere, cylinder, capsule), ``size`` (3,) (box extents; sphere ``(d, d, d)``; cylinder
    and capsule ``(2 r, 2 r, length)`` along their z), ``rgba`` (4,) in [0, 1], ``pose`` in the
    world, ``class_id`` (an onion's true class, else None)."""

    @property
    def name(self) -> str: ...
    @property
    def kind(self) -> str: ...
    @property
    def size(self) -> np.ndarray: ...
    @property
    def rgba(self) -> np.ndarray: ...
    @property
    def pose(self) -> Pose: ...
    @property
    def class_id(self) -> int | None: ...


class Robot(Protocol):
    """A robot at one instant (``robot.world.RobotState``): its URDF, its root link's pose in
    the world (``base``), and ``positions`` (n,) of its ``joint_names``."""

    @property
    def name(self) -> str: ...
    @property
    def urdf(self) -> Path: ...
    @property
    def base(self) -> Pose: ...
    @property
    def joint_names(self) -> tuple[str, ...]: ...
    @property
    def positions(self) -> np.ndarray: ...


class World(Protocol):
    """A snapshot of a simulated world (``robot.world.WorldState``): its ``shapes``, each
    camera's optical frame by ``frame_id`` (``cameras``), and its ``robot`` (or None)."""

    @property
    def shapes(self) -> Sequence[Shape]: ...
    @property
    def cameras(self) -> Mapping[str, Pose]: ...
    @property
    def robot(self) -> Robot | None: ...


def _stamp(msg, time_ns: int) -> None:
    msg.timestamp.seconds, msg.timestamp.nanos = divmod(int(time_ns), 1_000_000_000)


def _set_pose(msg, position, orientation) -> None:
    msg.position.x, msg.position.y, msg.position.z = (float(v) for v in position)
    q = msg.orientation
    q.x, q.y, q.z, q.w = (float(v) for v in orientation)


def _add_transform(msg: FrameTransforms, parent: str, child: str, translation, rotation,
                   time_ns: int) -> None:
    tf = msg.transforms.add(parent_frame_id=parent, child_frame_id=child)
    _stamp(tf, time_ns)
    tf.translation.x, tf.translation.y, tf.translation.z = (float(v) for v in translation)
    tf.rotation.x, tf.rotation.y, tf.rotation.z, tf.rotation.w = (float(v) for v in rotation)


def frame_transforms(world: World, time_ns: int, kinematics: UrdfJoints | None = None
                     ) -> FrameTransforms:
    """``/tf`` of ``world``: ``world`` -> each camera; with a robot, ``world`` -> its root link
    (``kinematics``, the robot's URDF, gives the root's name and the joints' transforms)."""
    msg = FrameTransforms()
    for frame_id, pose in world.cameras.items():
        _add_transform(msg, WORLD_FRAME, frame_id, pose.position, pose.orientation, time_ns)
    robot = world.robot
    if robot is not None:
        if kinematics is None:
            raise ValueError("a world with a robot needs its URDF's kinematics")
        _add_transform(msg, WORLD_FRAME, kinematics.root, robot.base.position,
                       robot.base.orientation, time_ns)
        positions = dict(zip(robot.joint_names, np.asarray(robot.positions, float).tolist(),
                             strict=True))
        for link in kinematics.transforms(positions):
            _add_transform(msg, link.parent, link.child, link.translation, link.rotation,
                           time_ns)
    return msg


def joint_states(robot: Robot, time_ns: int) -> JointStates:
    """``/joint_states`` of ``robot``: each joint's name and position."""
    msg = JointStates()
    _stamp(msg, time_ns)
    for name, q in zip(robot.joint_names, np.asarray(robot.positions, float), strict=True):
        msg.joints.add(name=name, position=float(q))
    return msg


def _color(msg, shape: Shape) -> None:
    if shape.class_id is not None:
        rgba = (*(c / 255.0 for c in CLASS_COLORS[int(shape.class_id)]), 1.0)
    else:
        rgba = np.asarray(shape.rgba, float)
    msg.color.r, msg.color.g, msg.color.b, msg.color.a = (float(v) for v in rgba)


def _size(msg, size) -> None:
    msg.size.x, msg.size.y, msg.size.z = (float(v) for v in size)


def scene_update(shapes: Sequence[Shape], time_ns: int) -> SceneUpdate:
    """``/scene``: one entity per shape (its ``name`` the id), in the ``world`` frame; an onion
    (a shape with a ``class_id``) in its class's colour. Foxglove has no capsule: a capsule is a
    cylinder with a sphere on each end."""
    msg = SceneUpdate()
    for shape in shapes:
        if shape.kind not in _KINDS:
            raise ValueError(f"shape {shape.name!r}: kind must be one of {_KINDS}; got "
                             f"{shape.kind!r}")
        entity = msg.entities.add(frame_id=WORLD_FRAME, id=shape.name)
        _stamp(entity, time_ns)
        entity.metadata.add(key="shape", value=shape.kind)
        if shape.class_id is not None:
            entity.metadata.add(key="class", value=CLASS_NAMES[int(shape.class_id)])
        pos, orn = shape.pose.position, shape.pose.orientation
        size = np.asarray(shape.size, float)
        if shape.kind == "box":
            prim = entity.cubes.add()
        elif shape.kind == "sphere":
            prim = entity.spheres.add()
        else:
            prim = entity.cylinders.add(bottom_scale=1.0, top_scale=1.0)
        _set_pose(prim.pose, pos, orn)
        _size(prim, size)
        _color(prim, shape)
        if shape.kind == "capsule":
            axis = _rotate(np.asarray(orn, float), np.array([0.0, 0.0, size[2] / 2]))
            for end in (-1.0, 1.0):
                cap = entity.spheres.add()
                _set_pose(cap.pose, np.asarray(pos, float) + end * axis, orn)
                _size(cap, [size[0]] * 3)
                _color(cap, shape)
    return msg


def _rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``v`` (3,) rotated by the unit quaternion ``q`` (x, y, z, w)."""
    u, w = q[:3], q[3]
    return v + 2.0 * np.cross(u, np.cross(u, v) + w * v)


def robot_record(robot: Robot, kinematics: UrdfJoints) -> dict[str, str]:
    """The ``onionsort.robot`` metadata record of a session with ``robot``: its name, URDF,
    root link and joint names (values as JSON where they are not strings)."""
    return {"name": str(robot.name), "urdf": str(Path(robot.urdf).resolve()),
            "root_link": kinematics.root, "joints": json.dumps(list(robot.joint_names))}


# -- reading back -----------------------------------------------------------------------------
#: A ``/tf`` transform as read back: ``(parent, translation (3,), rotation (4,))``.
Transform = tuple[str, np.ndarray, np.ndarray]


def read_transforms(data: bytes) -> dict[str, Transform]:
    """A ``/tf`` message's transforms by child frame."""
    out = {}
    for tf in FrameTransforms.FromString(data).transforms:
        t, r = tf.translation, tf.rotation
        out[tf.child_frame_id] = (tf.parent_frame_id, np.array([t.x, t.y, t.z]),
                                  np.array([r.x, r.y, r.z, r.w]))
    return out


def read_joint_states(data: bytes) -> dict[str, float]:
    """A ``/joint_states`` message's joint positions by name."""
    return {j.name: float(j.position) for j in JointStates.FromString(data).joints}


@dataclass(frozen=True)
class SceneItem:
    """A ``/scene`` entity as read back: a :class:`Shape` with its pose flattened into
    ``position`` (3,) and ``orientation`` (4,); ``class_id`` is None but for onions."""

    name: str
    kind: str
    size: np.ndarray = field(repr=False)
    position: np.ndarray = field(repr=False)
    orientation: np.ndarray = field(repr=False)
    rgba: np.ndarray = field(repr=False)
    class_id: int | None = None


def read_scene(data: bytes) -> list[SceneItem]:
    """A ``/scene`` message's entities, one item per shape (a capsule's end spheres folded back
    into the capsule)."""
    classes = {name: cid for cid, name in CLASS_NAMES.items()}
    out = []
    for entity in SceneUpdate.FromString(data).entities:
        meta = {kv.key: kv.value for kv in entity.metadata}
        kind = meta.get("shape")
        prims = {"box": entity.cubes, "sphere": entity.spheres, "cylinder": entity.cylinders,
                 "capsule": entity.cylinders}.get(kind)
        if not prims:  # not written by this module: take its first primitive as it is
            kind, prims = next(((k, v) for k, v in (("box", entity.cubes),
                                                     ("sphere", entity.spheres),
                                                     ("cylinder", entity.cylinders)) if v),
                               (None, None))
            if kind is None:
                continue
        prim = prims[0]
        pos, q, s, c = prim.pose.position, prim.pose.orientation, prim.size, prim.color
        out.append(SceneItem(
            name=entity.id, kind=kind, size=np.array([s.x, s.y, s.z]),
            position=np.array([pos.x, pos.y, pos.z]), orientation=np.array([q.x, q.y, q.z, q.w]),
            rgba=np.array([c.r, c.g, c.b, c.a]), class_id=classes.get(meta.get("class"))))
    return out
