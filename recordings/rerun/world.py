"""The work cell in 3D in Rerun: its bodies, its cameras, and a robot from its URDF.

A logger with an entity root (``record``, ``evaluate``) shows its world in one
``Spatial3DView`` at that root (:func:`world_view`), whose contents are the bodies, the robot and
the cameras that are pinholes (an image without one cannot be placed in 3D); the depth cloud
starts hidden there where the bodies or the robot are shown. :class:`WorldLogger` logs into it::

    <root>                            ViewCoordinates (static): the world, right-handed, z up
    <root>/camera                     Transform3D: the camera's optical frame in the world; with
                                      its Pinhole and images a frustum showing the image (and
                                      the depth as points) in 3D
    <root>/inspection                 the same for the inspection view
    <root>/scene/<group>/<kind>       the bodies of a group (``workcell``, ``gate``, ``sorter``,
                                      ``passer_by``, ``onions``) as Boxes3D, Ellipsoids3D,
                                      Cylinders3D or Capsules3D; onions with ``class_ids`` (the
                                      class colours of the annotation context)
    <root>/robot/<name>/...           the robot's URDF (static): its visual meshes, loaded by
                                      Rerun's URDF loader from a copy with ``.stl`` meshes
                                      (:func:`recordings.session.urdf.viewer_urdf`)
    <root>/robot/base                 Transform3D ``tf#/<root>`` -> the URDF's root link
    <root>/robot/joints/<joint>       Transform3D of each moving joint (parent -> child link)
                                      at every frame, from ``UrdfJoint.compute_transform``
    /tf_static                        the URDF's joint origins (static, from the loader)

A body or camera pose is logged again only when it changed, so the static work cell costs one
row. The robot's joints are sent whole (one ``send_columns`` call per joint).
"""

from __future__ import annotations

import hashlib
import logging
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
import rerun.urdf as rru

from recordings.session.schema import CLASS_NAMES
from recordings.session.urdf import viewer_urdf
from recordings.session.world import SceneItem, Shape

__all__ = ["WORK_CELL_EYE", "WorldLogger", "scene_items", "world_view"]

logger = logging.getLogger(__name__)

_PLURAL = {"box": "boxes", "sphere": "spheres", "cylinder": "cylinders", "capsule": "capsules"}


#: Where a 3D view of the work cell looks from and at (world metres, z up), for a cell laid
#: out as ``robot.scene`` lays it (the belt along x through the origin, 0.8 m up, the Sawyer
#: and the person behind it at y > 0): from the front right, above the camera, at the belt.
WORK_CELL_EYE = ((2.0, -3.2, 2.6), (0.0, 0.1, 1.0))


def world_view(root: str, name: str = "work cell (3D)", *,
               cameras: Sequence[str] = ("camera",), world: bool = False
               ) -> rrb.Spatial3DView:
    """The one 3D view of a blueprint, in the world frame of ``root``: the bodies
    (``<root>/scene``), the robot (``<root>/robot``) and the cameras ``cameras`` (names under
    ``root``, each a pinhole, with what is under it; ``"inspection/view_0"`` takes that image
    and its pinhole parent ``inspection`` only).

    Nothing else under ``root`` is shown: a 2D entity outside a pinhole's subtree has no place
    in 3D (the viewer reports it as an error), and series and text have none either. With
    ``world`` (the bodies or the robot are logged) the view looks at the work cell from
    :data:`WORK_CELL_EYE`, and the depth cloud of ``<root>/camera/depth`` starts hidden (a
    person turns it on in the view's entity list), so that the bodies and the robot are seen,
    not the points that cover them.
    """
    contents = ["$origin", "$origin/scene/**", "$origin/robot/**"]
    for camera in cameras:
        parent = camera.rsplit("/", 1)[0] if "/" in camera else None
        contents += ([f"$origin/{parent}"] if parent else []) + [f"$origin/{camera}/**"]
    if not world:
        return rrb.Spatial3DView(origin=root, contents=contents, name=name)
    position, target = WORK_CELL_EYE
    return rrb.Spatial3DView(
        origin=root, contents=contents, name=name,
        overrides={f"{root}/camera/depth": rrb.EntityBehavior(visible=False)},
        eye_controls=rrb.EyeControls3D(position=position, look_target=target,
                                       eye_up=(0.0, 0.0, 1.0)))


def scene_items(shapes: Iterable[Shape]) -> list[SceneItem]:
    """A world snapshot's shapes as :class:`recordings.session.world.SceneItem` (what the reader
    gives back from ``/scene``)."""
    return [SceneItem(name=s.name, kind=s.kind, size=np.asarray(s.size, float),
                      position=np.asarray(s.pose.position, float),
                      orientation=np.asarray(s.pose.orientation, float),
                      rgba=np.asarray(s.rgba, float), class_id=s.class_id) for s in shapes]


def _rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    u, w = q[:3], q[3]
    return v + 2.0 * np.cross(u, np.cross(u, v) + w * v)


class WorldLogger:
    """Logs a world's 3D side under ``root`` of recording ``rec``.

    Parameters
    ----------
    rec : rerun.RecordingStream
    root : str
        The entity root of the logger that owns the world (``record``, ``evaluate``).
    """

    def __init__(self, rec: rr.RecordingStream, root: str) -> None:
        self.rec, self.root = rec, root.strip("/")
        self._last: dict[str, bytes] = {}
        self._trees: dict[Path, rru.UrdfTree | None] = {}
        rec.log(self.root, rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)

    def _changed(self, entity: str, *arrays) -> bool:
        """Whether ``arrays`` differ from what was last logged at ``entity`` (and remember
        them)."""
        digest = hashlib.sha1(b"".join(np.ascontiguousarray(a).tobytes() for a in arrays) +
                              repr([np.shape(a) for a in arrays]).encode()).digest()
        if self._last.get(entity) == digest:
            return False
        self._last[entity] = digest
        return True

    def log_pose(self, entity: str, position: Sequence[float], orientation: Sequence[float],
                 *, static: bool = False) -> None:
        """Place ``entity`` (and its children: a camera's pinhole and images) at ``position``
        (3,) with quaternion ``orientation`` (4,) (x, y, z, w) in its parent."""
        position = np.asarray(position, float)
        orientation = np.asarray(orientation, float)
        if static or self._changed(entity, position, orientation):
            self.rec.log(entity, rr.Transform3D(translation=position,
                                                quaternion=rr.Quaternion(xyzw=orientation)),
                         static=static)

    def log_scene(self, items: Sequence[SceneItem]) -> None:
        """Log the bodies ``items`` at the current time, one batch per group and kind; a
        batch equal to the one last logged is not logged again."""
        batches: dict[str, list[SceneItem]] = {}
        for item in items:
            group = item.name.split("/", 1)[0] if "/" in item.name else item.name
            if item.kind not in _PLURAL:
                raise ValueError(f"scene item {item.name!r}: kind must be one of "
                                 f"{sorted(_PLURAL)}; got {item.kind!r}")
            batches.setdefault(f"{self.root}/scene/{group}/{_PLURAL[item.kind]}", []).append(item)
        for entity, batch in batches.items():
            size = np.array([b.size for b in batch], float)
            centers = np.array([b.position for b in batch], float)
            quats = np.array([b.orientation for b in batch], float)
            rgba = np.clip(np.round(np.array([b.rgba for b in batch], float) * 255), 0, 255)
            classes = [b.class_id for b in batch]
            if not self._changed(entity, size, centers, quats, rgba, np.array(
                    [-1 if c is None else c for c in classes])):
                continue
            labeled = all(c is not None for c in classes)
            common = {
                "quaternions": [rr.Quaternion(xyzw=q) for q in quats],
                "labels": [_label(b) for b in batch], "show_labels": False,
                "fill_mode": rr.components.FillMode.Solid,
            }
            if labeled:
                common["class_ids"] = [int(c) for c in classes]
            else:
                common["colors"] = rgba.astype(np.uint8)
            kind = batch[0].kind
            if kind == "box":
                archetype = rr.Boxes3D(centers=centers, half_sizes=size / 2, **common)
            elif kind == "sphere":
                archetype = rr.Ellipsoids3D(centers=centers, half_sizes=size / 2, **common)
            elif kind == "cylinder":
                archetype = rr.Cylinders3D(centers=centers, lengths=size[:, 2],
                                           radii=size[:, 0] / 2, **common)
            else:  # a capsule runs from its translation along +z for its length
                ends = np.array([c - _rotate(q, np.array([0.0, 0.0, s[2] / 2]))
                                 for c, q, s in zip(centers, quats, size, strict=True)])
                archetype = rr.Capsules3D(translations=ends, lengths=size[:, 2],
                                          radii=size[:, 0] / 2, **common)
            self.rec.log(entity, archetype)

    def robot_model(self, urdf: str | Path) -> rru.UrdfTree | None:
        """Log the robot of ``urdf`` (static, once per file) under ``<root>/robot`` and return
        its kinematic tree; None (with a warning) if the URDF or its meshes cannot be read."""
        urdf = Path(urdf)
        if urdf in self._trees:
            return self._trees[urdf]
        try:
            viewer = viewer_urdf(urdf)
            tree = rru.UrdfTree.from_file_path(viewer)
        except (OSError, ValueError, RuntimeError) as exc:
            logger.warning("the robot's URDF %s cannot be read (%s: %s); the robot is left "
                           "out of the 3D view", urdf, type(exc).__name__, exc)
            self._trees[urdf] = None
            return None
        self.rec.log_file_from_path(viewer, entity_path_prefix=f"{self.root}/robot",
                                    static=True)
        self._trees[urdf] = tree
        return tree

    def log_robot_base(self, tree: rru.UrdfTree, position: Sequence[float],
                       orientation: Sequence[float], *, static: bool = False) -> None:
        """Stand the robot's root link at ``position`` (3,), ``orientation`` (4,) in the world
        frame of ``<root>``."""
        position = np.asarray(position, float)
        orientation = np.asarray(orientation, float)
        entity = f"{self.root}/robot/base"
        if static or self._changed(entity, position, orientation):
            self.rec.log(entity, rr.Transform3D(
                translation=position, quaternion=rr.Quaternion(xyzw=orientation),
                parent_frame=f"tf#/{self.root}", child_frame=tree.root_link().name),
                static=static)

    def send_joints(self, tree: rru.UrdfTree, joint_names: Sequence[str],
                    positions: np.ndarray, indexes: Iterable[rr.TimeColumn]) -> None:
        """Send the transforms of ``joint_names`` at ``positions`` (n, n_joints), one row per
        time of ``indexes``, one ``send_columns`` call per joint."""
        positions = np.asarray(positions, float)
        if positions.ndim != 2 or positions.shape[1] != len(joint_names):
            raise ValueError(f"positions must have shape (n, {len(joint_names)}) for joints "
                             f"{list(joint_names)}; got {positions.shape}")
        indexes = list(indexes)
        for k, name in enumerate(joint_names):
            joint = tree.get_joint_by_name(name)
            if joint is None:
                raise ValueError(f"the URDF of {tree.name!r} has no joint {name!r}")
            self.rec.send_columns(f"{self.root}/robot/joints/{name}", indexes=indexes,
                                  columns=joint.compute_transform_columns(positions[:, k],
                                                                          clamp=False))


def _label(item: SceneItem) -> str:
    if item.class_id is not None:
        return f"{CLASS_NAMES.get(int(item.class_id), item.class_id)} {item.name}"
    return item.name
