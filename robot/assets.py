"""Where the robot's assets come from: the Sawyer URDF shipped in the robosuite wheel.

robosuite is used only as an asset package (installed with ``--no-deps`` because its own
dependencies pin numpy below 2), so it is located with :func:`importlib.util.find_spec` and never
imported.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

__all__ = ["ROBOSUITE_INSTALL", "AssetNotFoundError", "sawyer_urdf"]

ROBOSUITE_INSTALL = "pip install --no-deps robosuite==1.5.2"
"""The install command that provides the Sawyer URDF and meshes."""

_SAWYER_DIR = Path("models", "assets", "bullet_data", "sawyer_description")


class AssetNotFoundError(FileNotFoundError):
    """A robot asset is missing; the message says how to install it."""


def sawyer_urdf() -> Path:
    """Path of the official Sawyer arm URDF (``sawyer_description/urdf/sawyer_arm.urdf``).

    Raises
    ------
    AssetNotFoundError
        If robosuite is not installed or its wheel lacks the URDF; the message names the install
        command.
    """
    spec = importlib.util.find_spec("robosuite")
    if spec is None or not spec.submodule_search_locations:
        raise AssetNotFoundError(
            "the Sawyer URDF comes from the robosuite asset package, which is not installed; "
            f"install it with `{ROBOSUITE_INSTALL}`"
        )
    for root in spec.submodule_search_locations:
        urdf = Path(root) / _SAWYER_DIR / "urdf" / "sawyer_arm.urdf"
        if urdf.is_file():
            return urdf
    raise AssetNotFoundError(
        f"robosuite is installed at {list(spec.submodule_search_locations)} but has no "
        f"{_SAWYER_DIR}/urdf/sawyer_arm.urdf; reinstall it with `{ROBOSUITE_INSTALL}`"
    )
