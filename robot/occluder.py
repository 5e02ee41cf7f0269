"""The passer-by: someone who walks between the camera and the workspace at random steps.

:func:`occlusion_schedule` decides which abstract steps are occluded (independently, with the
requested rate); :class:`PasserBy` walks across the view during those steps and waits out of
sight otherwise. How much of the view is blocked varies with the walker's build and distance.

A *partial* crossing (:meth:`PasserBy.start_crossing` with ``partial=True``, the
``partial_occlusion`` knob of :mod:`robot.difficulty`) walks past the left or right edge of the
view, covering 8-30 % of its width and leaving the workspace in view.
"""

from __future__ import annotations

import numpy as np
import pybullet as p

__all__ = ["PasserBy", "occlusion_schedule"]

_PARKED = np.array([0.0, -6.0, 0.0])


def occlusion_schedule(n_steps: int, rate: float, rng: np.random.Generator) -> np.ndarray:
    """Which of ``n_steps`` steps the passer-by crosses: Bernoulli(``rate``) each, shape (T,)."""
    if n_steps < 1:
        raise ValueError(f"n_steps must be >= 1; got {n_steps}")
    if not 0.0 <= rate <= 1.0:
        raise ValueError(f"rate must be in [0, 1]; got {rate}")
    return rng.random(n_steps) < rate


class PasserBy:
    """A walker built from primitives (torso, head, legs) that crosses the camera's view.

    Parameters
    ----------
    client : int
        PyBullet physics client id.
    rng : numpy.random.Generator
        Draws the walker's build and clothes, and each crossing's depth and direction.
    camera_eye, workspace : array of shape (3,)
        The camera and the point it looks at; crossings happen between them.
    """

    def __init__(self, client: int, rng: np.random.Generator, camera_eye, workspace) -> None:
        self.client = client
        self.rng = rng
        self.camera_eye = np.asarray(camera_eye, float)
        self.workspace = np.asarray(workspace, float)
        self.width = float(rng.uniform(0.17, 0.26))
        coat = [*rng.uniform(0.05, 0.9, 3).tolist(), 1.0]
        skin = [*rng.uniform([0.3, 0.2, 0.15], [0.95, 0.75, 0.6]).tolist(), 1.0]
        self._parts = []  # (body id, offset from the walker's ground point)
        for shape, rgba, offset, kwargs in (
            (p.GEOM_CAPSULE, coat, [0, 0, 1.2], {"radius": self.width, "length": 0.5}),
            (p.GEOM_SPHERE, skin, [0, 0, 1.68], {"radius": 0.11}),
            (p.GEOM_BOX, [0.1, 0.1, 0.12, 1.0], [0, 0, 0.45],
             {"halfExtents": [self.width * 0.8, 0.1, 0.45]}),
        ):
            vis = p.createVisualShape(shape, rgbaColor=rgba, physicsClientId=client, **kwargs)
            body = p.createMultiBody(0, -1, vis, basePosition=(_PARKED + offset).tolist(),
                                     physicsClientId=client)
            self._parts.append((body, np.asarray(offset, float)))
        self.body_ids = tuple(b for b, _ in self._parts)
        self._crossing: tuple[np.ndarray, np.ndarray] | None = None

    def place(self, ground: np.ndarray) -> None:
        """Put the walker's ground point at ``ground`` (3,)."""
        for body, offset in self._parts:
            p.resetBasePositionAndOrientation(
                body, (np.asarray(ground) + offset).tolist(), [0, 0, 0, 1],
                physicsClientId=self.client,
            )

    def start_crossing(self, partial: bool = False, rng: np.random.Generator | None = None,
                       tan_half_fov: float = 0.54) -> None:
        """Draw a crossing: a depth between camera and workspace and a walking direction.

        With ``partial`` the walker passes the edge of the view instead (drawn from ``rng``,
        by default the walker's own): its inner side 8-30 % of the view's width in from the
        left or right edge (``tan_half_fov``: tangent of the camera's half horizontal field
        of view; the camera looks along +y, so x is across the view).
        """
        if partial:
            rng = self.rng if rng is None else rng
            frac = rng.uniform(0.5, 0.75)
            center = self.camera_eye + frac * (self.workspace - self.camera_eye)
            half_view = frac * np.linalg.norm(self.workspace - self.camera_eye) * tan_half_fov
            side = 1.0 if rng.random() < 0.5 else -1.0
            inner = center[0] + side * half_view * (1.0 - 2.0 * rng.uniform(0.08, 0.3))
            center[0], center[2] = inner + side * self.width, 0.0
            step = rng.uniform(-0.05, 0.05) * np.array([1.0, 0.0, 0.0])
            self._crossing = (center - step, center + step)
            return
        depth = self.rng.uniform(0.3, 0.6)  # fraction of the way from camera to workspace
        center = self.camera_eye + depth * (self.workspace - self.camera_eye)
        center[2] = 0.0
        half = self.rng.uniform(0.1, 0.3) * np.array([1.0, 0.0, 0.0])
        sign = 1.0 if self.rng.random() < 0.5 else -1.0
        jitter = self.rng.uniform(-0.1, 0.1) * np.array([1.0, 0.0, 0.0])
        self._crossing = (center + jitter - sign * half, center + jitter + sign * half)

    def walk(self, phase: float | None) -> None:
        """Walk to ``phase`` in [0, 1] of the current crossing, or park out of sight if None."""
        if phase is None or self._crossing is None:
            self.place(_PARKED)
            return
        start, end = self._crossing
        self.place(start + float(np.clip(phase, 0.0, 1.0)) * (end - start))
