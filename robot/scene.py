"""The static workcell and the onions on it: floor, conveyor on its stand, bin, onion pool.

The belt does not simulate friction: onions ride it kinematically (:meth:`Conveyor.advance`),
which keeps rendering deterministic and fast. All geometry comes from :mod:`robot.state_map`.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pybullet as p

from robot.onions import OnionAppearance, onion_texture, sample_appearance, save_texture
from robot.state_map import (
    BELT_HALF_LENGTH,
    BELT_HALF_WIDTH,
    BELT_TOP,
    BIN_CENTER,
    BIN_HALF_EXTENT,
    BIN_TOP,
    PICK_SPOT,
)

__all__ = ["GATE_X", "Onion", "OnionPool", "StopGate", "build_workcell", "connect"]

_LANES = (-0.04, 0.08)  # y range onions ride in (reachable by the sorter)
GATE_X = float(PICK_SPOT[0]) + 0.06
"""Position along the belt of the stop gate that holds a claimed onion at the pick spot."""
_QUEUE_SPACING = 0.07  # distance between onions queued behind the raised gate


def connect() -> int:
    """A new headless (DIRECT) PyBullet client with gravity; returns its id."""
    client = p.connect(p.DIRECT)
    p.setGravity(0, 0, -9.81, physicsClientId=client)
    return client


def _box(client: int, half, center, rgba, collide: bool = False) -> int:
    vis = p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=rgba,
                              physicsClientId=client)
    col = (p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client)
           if collide else -1)
    return p.createMultiBody(0, col, vis, basePosition=list(center), physicsClientId=client)


def build_workcell(client: int, rng: np.random.Generator) -> dict[str, int]:
    """Create floor, conveyor (belt and stand), bin and its stand; returns name -> body id.

    The floor and belt tints vary with ``rng`` (part of the scene's appearance variation).
    """
    floor_tint = rng.uniform(0.35, 0.6)
    ids = {
        "floor": _box(client, [4, 4, 0.01], [0, 0, -0.01],
                      [floor_tint, floor_tint * 0.95, floor_tint * 0.9, 1], collide=True),
        "belt": _box(client, [BELT_HALF_LENGTH, BELT_HALF_WIDTH, 0.02],
                     [0, 0, BELT_TOP - 0.02], [*(rng.uniform(0.12, 0.22) * np.ones(3)), 1],
                     collide=True),
    }
    for i, (sx, sy) in enumerate([(-1, -1), (-1, 1), (1, -1), (1, 1)]):  # the stand
        ids[f"stand_leg_{i}"] = _box(
            client, [0.03, 0.03, (BELT_TOP - 0.04) / 2],
            [sx * (BELT_HALF_LENGTH - 0.1), sy * (BELT_HALF_WIDTH - 0.03), (BELT_TOP - 0.04) / 2],
            [0.55, 0.57, 0.6, 1],
        )
    for side in ("rail_near", "rail_far"):
        y = -(BELT_HALF_WIDTH + 0.01) if side == "rail_near" else BELT_HALF_WIDTH + 0.01
        ids[side] = _box(client, [BELT_HALF_LENGTH, 0.01, 0.025], [0, y, BELT_TOP + 0.005],
                         [0.6, 0.62, 0.65, 1])
    bin_rgba = [0.15, 0.35, 0.7, 1]
    cx, cy = BIN_CENTER[:2]
    e = BIN_HALF_EXTENT
    ids["bin_floor"] = _box(client, [e, e, 0.01], [cx, cy, BIN_TOP - 0.3], bin_rgba)
    ids["bin_stand"] = _box(client, [e * 0.8, e * 0.8, (BIN_TOP - 0.31) / 2],
                            [cx, cy, (BIN_TOP - 0.31) / 2], [0.45, 0.45, 0.45, 1])
    for name, half, off in (
        ("bin_wall_0", [e, 0.01, 0.15], [0, -e, 0]), ("bin_wall_1", [e, 0.01, 0.15], [0, e, 0]),
        ("bin_wall_2", [0.01, e, 0.15], [-e, 0, 0]), ("bin_wall_3", [0.01, e, 0.15], [e, 0, 0]),
    ):
        ids[name] = _box(client, half, [cx + off[0], cy + off[1], BIN_TOP - 0.15], bin_rgba)
    return ids


class StopGate:
    """The pneumatic stop gate across the belt, just downstream of the pick spot.

    Claiming an onion raises the gate: the claimed onion waits at the pick spot and the onions
    behind it queue. Picking the onion (or placing it back) lowers the gate into the belt's
    frame, out of sight. On a real line the raised gate is the visible sign that an onion has
    been claimed; the state classifier reads it.
    """

    _HALF = (0.02, BELT_HALF_WIDTH, 0.05)

    def __init__(self, client: int) -> None:
        self.client = client
        self.body = _box(client, list(self._HALF), self._center(False), [1.0, 0.45, 0.05, 1])
        self.raised = False

    def _center(self, raised: bool) -> list[float]:
        z = BELT_TOP + self._HALF[2] if raised else BELT_TOP - self._HALF[2] - 0.005
        return [GATE_X, 0.0, z]

    def set(self, raised: bool) -> None:
        """Raise or lower the gate."""
        if raised != self.raised:
            p.resetBasePositionAndOrientation(self.body, self._center(raised), [0, 0, 0, 1],
                                              physicsClientId=self.client)
            self.raised = raised


@dataclass
class Onion:
    """One onion body and where it is: ``"belt"``, ``"held"`` or ``"bin"``."""

    onion_id: int
    body: int
    appearance: OnionAppearance
    position: np.ndarray
    place: str = "belt"

    @property
    def blemished(self) -> bool:
        return self.appearance.blemished


class OnionPool:
    """A fixed pool of textured onions that ride the belt and recycle from its end and the bin.

    Parameters
    ----------
    client : int
        PyBullet physics client id.
    n_onions : int
        Pool size.
    blemish_rate : float
        Probability that an onion is blemished.
    rng : numpy.random.Generator
    texture_size : int
        Side of each onion's texture in pixels.
    blemish_subtlety, one_sided_blemish : float
        How subtle blemishes are (see :func:`robot.onions.onion_texture`); 0 for today's.
    """

    def __init__(self, client: int, n_onions: int, blemish_rate: float,
                 rng: np.random.Generator, texture_size: int = 64, *,
                 blemish_subtlety: float = 0.0, one_sided_blemish: float = 0.0) -> None:
        if n_onions < 2:
            raise ValueError(f"n_onions must be >= 2; got {n_onions}")
        if not 0.0 <= blemish_rate <= 1.0:
            raise ValueError(f"blemish_rate must be in [0, 1]; got {blemish_rate}")
        self.client, self.rng = client, rng
        self.onions: list[Onion] = []
        self.textures: dict[int, int] = {}  # body -> its texture's PyBullet id
        self.bin_order: list[int] = []
        xs = np.linspace(-BELT_HALF_LENGTH + 0.1, BELT_HALF_LENGTH - 0.1, n_onions)
        xs = xs + rng.uniform(-0.05, 0.05, n_onions)
        with tempfile.TemporaryDirectory(prefix="onion-textures-") as tmp:
            for i in range(n_onions):
                look = sample_appearance(rng, blemished=rng.random() < blemish_rate)
                tex = onion_texture(look, texture_size, subtlety=blemish_subtlety,
                                    one_sided=one_sided_blemish)
                png = save_texture(tex, Path(tmp) / f"{i}.png")
                texture = p.loadTexture(str(png), physicsClientId=client)
                vis = p.createVisualShape(p.GEOM_SPHERE, radius=look.radius,
                                          rgbaColor=[1, 1, 1, 1], physicsClientId=client)
                pos = np.array([xs[i], rng.uniform(*_LANES), BELT_TOP + look.radius])
                body = p.createMultiBody(0, -1, vis, basePosition=pos.tolist(),
                                         physicsClientId=client)
                p.changeVisualShape(body, -1, textureUniqueId=texture, physicsClientId=client)
                self.textures[body] = texture
                self.onions.append(Onion(i, body, look, pos))

    @property
    def body_ids(self) -> list[int]:
        return [o.body for o in self.onions]

    def move(self, onion: Onion, position: np.ndarray, yaw: float = 0.0) -> None:
        """Put ``onion`` at ``position`` (3,), turned by ``yaw`` radians about the vertical."""
        onion.position = np.asarray(position, float).copy()
        turn = [0.0, 0.0, float(np.sin(yaw / 2)), float(np.cos(yaw / 2))]
        p.resetBasePositionAndOrientation(onion.body, onion.position.tolist(), turn,
                                          physicsClientId=self.client)

    def advance(self, distance: float, stop: tuple[Onion, float] | None = None) -> None:
        """Carry every onion on the belt ``distance`` metres downstream.

        An onion reaching the belt's end re-enters at its start (out of the camera's view).
        ``stop = (onion, x)`` holds one onion at a raised stop gate: it rides only until ``x``,
        and the onions upstream of it queue behind it.
        """
        limit = None
        if stop is not None:
            held, stop_x = stop
            x = min(held.position[0] + distance, max(stop_x, held.position[0]))
            self.move(held, [x, held.position[1], held.position[2]])
            limit = x - _QUEUE_SPACING
        riding = sorted((o for o in self.onions
                         if o.place == "belt" and (stop is None or o is not stop[0])),
                        key=lambda o: -o.position[0])
        for onion in riding:
            x = onion.position[0] + distance
            if limit is not None and onion.position[0] <= limit + 1e-9:
                x = min(x, max(limit, onion.position[0]))
                limit = x - _QUEUE_SPACING
            elif x > BELT_HALF_LENGTH - 0.05:
                x -= 2 * BELT_HALF_LENGTH - 0.1
            self.move(onion, [x, onion.position[1], onion.position[2]])

    def drop_in_bin(self, onion: Onion, max_in_bin: int = 4) -> None:
        """Put ``onion`` in the bin; the oldest bin onion beyond ``max_in_bin`` returns upstream."""
        onion.place = "bin"
        offset = self.rng.uniform(-0.6, 0.6, 2) * BIN_HALF_EXTENT
        self.move(onion, [BIN_CENTER[0] + offset[0], BIN_CENTER[1] + offset[1],
                          BIN_TOP - 0.29 + onion.appearance.radius])
        self.bin_order.append(onion.onion_id)
        while len(self.bin_order) > max_in_bin:
            old = self.onions[self.bin_order.pop(0)]
            self.put_on_belt(old, x=-BELT_HALF_LENGTH + 0.05)

    def put_on_belt(self, onion: Onion, x: float, y: float | None = None) -> None:
        """Put ``onion`` on the belt at ``x`` (and lane ``y``, drawn if None)."""
        if onion.onion_id in self.bin_order:
            self.bin_order.remove(onion.onion_id)
        onion.place = "belt"
        y = self.rng.uniform(*_LANES) if y is None else y
        self.move(onion, [x, y, BELT_TOP + onion.appearance.radius])
