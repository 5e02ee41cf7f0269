"""A robot's URDF for the viewers: its joints' transforms, and a copy whose meshes they can load.

:class:`UrdfJoints` reads the kinematic tree of a URDF (joints with their origin, axis and type)
and gives each joint's parent-link-to-child-link transform at given joint positions: the
``/tf`` of a session with a robot. :func:`viewer_urdf` writes a copy of a URDF that Rerun's URDF
loader and Foxglove can open without any ROS environment: ``package://`` mesh paths are resolved
to absolute paths here, Collada meshes (``.dae``, which Rerun does not render) are replaced by
the ``.stl`` meshes shipped beside them, and the collision geometry (drawn over the visual meshes
otherwise) is left out.

Conventions: translations (3,) in metres, rotations as quaternions ``(x, y, z, w)``; a URDF
``rpy`` is roll, pitch, yaw about the fixed x, y, z axes (``R = Rz(yaw) Ry(pitch) Rx(roll)``).
"""

from __future__ import annotations

import hashlib
import logging
import os
import re
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["JointSpec", "LinkTransform", "UrdfJoints", "rpy_quaternion", "viewer_urdf"]

logger = logging.getLogger(__name__)

_MOVING = ("revolute", "continuous", "prismatic")


def _quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The Hamilton product ``a * b`` of quaternions (x, y, z, w)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz])


def _axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    return np.array([*(axis * np.sin(angle / 2)), np.cos(angle / 2)])


def rpy_quaternion(rpy) -> np.ndarray:
    """The quaternion (x, y, z, w) of URDF roll, pitch, yaw (radians, fixed axes x, y, z)."""
    r, p, y = (float(v) for v in rpy)
    return _quat_multiply(_axis_angle([0, 0, 1], y),
                          _quat_multiply(_axis_angle([0, 1, 0], p), _axis_angle([1, 0, 0], r)))


def _floats(text: str | None, default: tuple[float, ...]) -> np.ndarray:
    return np.array(default if text is None else [float(v) for v in text.split()], float)


@dataclass(frozen=True)
class JointSpec:
    """One URDF joint: ``parent`` and ``child`` links, its ``origin`` (translation, quaternion)
    in the parent link, its ``axis`` (3,) in the joint frame, its ``kind`` (URDF type)."""

    name: str
    kind: str
    parent: str
    child: str
    translation: np.ndarray
    rotation: np.ndarray
    axis: np.ndarray


@dataclass(frozen=True)
class LinkTransform:
    """The pose of link ``child`` in link (or frame) ``parent``."""

    parent: str
    child: str
    translation: np.ndarray
    rotation: np.ndarray


class UrdfJoints:
    """The joints of a URDF and their transforms at given positions.

    Parameters
    ----------
    path : path-like
        The URDF file.

    Attributes
    ----------
    name : str
        The robot's name.
    joints : tuple of JointSpec
        Every joint, in file order.
    root : str
        The root link (the one that is no joint's child).

    Raises
    ------
    ValueError
        If the file is not a URDF with a single root link.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        try:
            robot = ET.parse(self.path).getroot()
        except ET.ParseError as exc:
            raise ValueError(f"{self.path} is not a readable URDF ({exc})") from None
        if robot.tag != "robot":
            raise ValueError(f"{self.path} is not a URDF: its root element is <{robot.tag}>, "
                             "not <robot>")
        self.name = robot.get("name", "robot")
        joints = []
        for j in robot.findall("joint"):
            origin = j.find("origin")
            axis = j.find("axis")
            joints.append(JointSpec(
                name=j.get("name"), kind=j.get("type"), parent=j.find("parent").get("link"),
                child=j.find("child").get("link"),
                translation=_floats(None if origin is None else origin.get("xyz"), (0, 0, 0)),
                rotation=rpy_quaternion(
                    _floats(None if origin is None else origin.get("rpy"), (0, 0, 0))),
                axis=_floats(None if axis is None else axis.get("xyz"), (1, 0, 0))))
        self.joints = tuple(joints)
        links = [link.get("name") for link in robot.findall("link")]
        children = {j.child for j in joints}
        roots = [link for link in links if link not in children]
        if len(roots) != 1:
            raise ValueError(f"{self.path}: a URDF needs exactly one root link; got {roots}")
        self.root = roots[0]

    @property
    def moving(self) -> tuple[str, ...]:
        """Names of the joints that move (revolute, continuous, prismatic), in file order."""
        return tuple(j.name for j in self.joints if j.kind in _MOVING)

    def transforms(self, positions: Mapping[str, float]) -> list[LinkTransform]:
        """Every joint's child link in its parent link, at ``positions`` (joint name ->
        radians or metres; a moving joint not named stays at 0)."""
        unknown = set(positions) - {j.name for j in self.joints}
        if unknown:
            raise ValueError(f"{self.path}: no joints named {sorted(unknown)}; its joints are "
                             f"{[j.name for j in self.joints]}")
        out = []
        for j in self.joints:
            t, q = j.translation.copy(), j.rotation.copy()
            value = float(positions.get(j.name, 0.0))
            if j.kind in ("revolute", "continuous"):
                q = _quat_multiply(q, _axis_angle(j.axis, value))
            elif j.kind == "prismatic":
                t = t + _rotate(q, j.axis / np.linalg.norm(j.axis) * value)
            out.append(LinkTransform(j.parent, j.child, t, q))
        return out


def _rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``v`` (3,) rotated by quaternion ``q`` (x, y, z, w)."""
    qv = np.array([*v, 0.0])
    conj = np.array([-q[0], -q[1], -q[2], q[3]])
    return _quat_multiply(_quat_multiply(q, qv), conj)[:3]


#: Version of the rewriting :func:`viewer_urdf` does (part of its cache key).
_VIEWER_COPY = 1
_PACKAGE = re.compile(r"package://([^/\"']+)/([^\"']+)")


def _package_root(urdf: Path, package: str) -> Path | None:
    """The folder of ROS package ``package`` above ``urdf``: one whose ``package.xml`` names it,
    or, without a ``package.xml``, one named like it."""
    for folder in urdf.resolve().parents:
        manifest = folder / "package.xml"
        if manifest.is_file():
            try:
                name = ET.parse(manifest).getroot().findtext("name")
            except ET.ParseError:
                name = None
            if (name or "").strip() == package:
                return folder
        elif folder.name == package:
            return folder
    return None


def _resolve_mesh(urdf: Path, package: str, relative: str) -> str:
    root = _package_root(urdf, package)
    if root is None:
        raise FileNotFoundError(f"{urdf}: no folder of package {package!r} (a package.xml "
                                f"naming it, or a folder of that name) above the URDF")
    mesh = root / relative
    if mesh.suffix.lower() == ".dae":
        stl = mesh.with_suffix(".stl")
        if stl.is_file():
            mesh = stl
        else:
            logger.warning("%s: %s is Collada, which Rerun does not render, and there is no "
                           "%s beside it", urdf, mesh, stl.name)
    if not mesh.is_file():
        raise FileNotFoundError(f"{urdf}: mesh {mesh} (package://{package}/{relative}) does not "
                                "exist")
    return str(mesh)


def viewer_urdf(urdf: str | Path, cache: str | Path | None = None) -> Path:
    """A copy of ``urdf`` for viewers: absolute mesh paths, ``.stl`` for ``.dae`` meshes, no
    ``<collision>`` elements.

    Parameters
    ----------
    urdf : path-like
        The URDF (its ``package://`` paths are resolved from the folders above it).
    cache : path-like or None
        Where to write the copy (a folder per source file and version); the system's temporary
        folder by default. An existing copy is reused.

    Returns
    -------
    Path
        The resolved copy, named like ``urdf``.

    Raises
    ------
    FileNotFoundError
        If ``urdf`` or one of its meshes does not exist.
    """
    src = Path(urdf)
    if not src.is_file():
        raise FileNotFoundError(f"{src}: no such URDF")
    text = src.read_text()
    key = hashlib.sha1(f"{_VIEWER_COPY}\n{src.resolve()}\n{text}".encode()).hexdigest()[:16]
    folder = Path(cache or Path(tempfile.gettempdir()) / "onionsort-urdf") / key
    out = folder / src.name
    if out.is_file():
        return out
    resolved = re.sub(r"\s*<collision\b.*?</collision>", "", text, flags=re.DOTALL)
    resolved = _PACKAGE.sub(lambda m: _resolve_mesh(src, m.group(1), m.group(2)), resolved)
    resolved = re.sub(r'filename="([^"]+\.dae)"',
                      lambda m: f'filename="{_relative_dae(src, m.group(1))}"', resolved)
    folder.mkdir(parents=True, exist_ok=True)
    tmp = folder / f".{src.name}.{os.getpid()}.partial"
    tmp.write_text(resolved)
    tmp.replace(out)
    return out


def _relative_dae(urdf: Path, filename: str) -> str:
    """A non-package ``.dae`` mesh path, made absolute, as its ``.stl`` sibling if there is one."""
    mesh = Path(filename)
    if not mesh.is_absolute():
        mesh = urdf.parent / mesh
    stl = mesh.with_suffix(".stl")
    return str(stl if stl.is_file() else mesh)
