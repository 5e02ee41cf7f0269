"""How the Sawyer shows an onion to its inspection camera: how many views, and the wrist's
pose for each (no simulation here, so that configurations and the CLI can read the defaults
without loading PyBullet)."""

from __future__ import annotations

import numpy as np

__all__ = ["INSPECTION_TILT", "INSPECTION_VIEWS", "inspection_poses"]

INSPECTION_VIEWS = 5
"""Views the Sawyer takes of every onion by default (see :func:`inspection_poses`): the fewest
whose fused call at `paper` and `hard` was within 0.02 of the best over 1 to 8 views, on tuning
frames of seed 8 (40 onions a level; docs/notes/2026-11-25-robot-inspection-tuning.md)."""
INSPECTION_TILT = np.deg2rad(40.0)
"""How far the tilted views turn the onion's underside towards the camera (radians)."""


def inspection_poses(n_views: int, tilt: float = INSPECTION_TILT
                     ) -> tuple[tuple[float, float], ...]:
    """``(yaw, tilt)`` in radians of each of ``n_views`` inspection views.

    The wrist turns the onion about the vertical by ``yaw``; the turns follow the base-2 van der
    Corput sequence of a full turn (0, 1/2, 1/4, 3/4, 1/8, ...), so that the first ``n`` views
    of any longer sequence are ``n`` views spread around the onion (and a dataset rendered with
    8 views holds the robot's views for every ``n_views`` up to 8). Every other view (``k``
    odd) also tilts the onion by ``tilt`` about the camera's horizontal axis, its underside
    towards the camera, where a gripper at the top and a camera a little above never look. The
    first view is the untilted pose at which the onion arrives.
    """
    if isinstance(n_views, bool) or not isinstance(n_views, int | np.integer) or n_views < 1:
        raise ValueError(f"n_views must be an int >= 1; got {n_views!r}")
    if not 0.0 <= float(tilt) <= np.pi / 2:
        raise ValueError(f"tilt must be in [0, pi/2] radians; got {tilt!r}")
    poses = []
    for k in range(int(n_views)):
        turn, bit, rest = 0.0, 0.5, k
        while rest:  # the radical inverse of k in base 2
            turn += bit * (rest & 1)
            rest, bit = rest >> 1, bit / 2
        yaw = float(np.angle(np.exp(-2j * np.pi * turn)))
        poses.append((yaw, float(tilt) if k % 2 else 0.0))
    return tuple(poses)
