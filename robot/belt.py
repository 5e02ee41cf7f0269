"""The Sawyer station's line-up of onions and its indexing belt: where each onion is.

The belt runs only while the station claims an onion: onion ``k`` of the line-up waits at the
raised gate (:data:`robot.scene.GATE_X`) when the belt has travelled ``k * SPACING``; onions set
back downstream ride away with it and leave the belt at its end. An onion is also held by the
Sawyer, in the bin (in layers of a 3 x 3 grid) or on the check tray beside it (where deferred
onions wait for a person). Onions are static, mass-0 bodies that the belt carries kinematically;
an onion off the belt (not yet arrived, or ridden away) is parked out of the world. Positions are
world metres, shape (3,).
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pybullet as p

from irl.domains.onion_sorting import Prediction
from robot.blemishes import BlemishProbe
from robot.difficulty import Difficulty
from robot.onions import OnionAppearance, onion_texture, sample_appearance, save_texture
from robot.scene import GATE_X
from robot.state_map import BELT_HALF_LENGTH, BELT_TOP, BIN_CENTER, BIN_TOP

__all__ = ["Belt", "LineUpOnion", "gate_stop_x", "in_world", "make_lineup"]

_LANES = (-0.04, 0.08)  # y range the onions ride in (as in robot.scene)
_SPACING = 0.25  # belt travel between consecutive onions of the line-up
_GATE_FACE = GATE_X - 0.02  # upstream face of the raised stop gate
_PARKED = (0.0, 0.0, -10.0)  # bodies off the belt (not yet arrived, or ridden away)
#: The check tray on the floor beside the bin, where deferred onions wait for a person: its
#: first slot; the others follow along x.
_TRAY = np.array([BIN_CENTER[0] + 0.42, BIN_CENTER[1], 0.0])
_BIN_SLOTS = 9  # onions per layer in the bin (3 x 3)
_BIN_LAYERS = 4


def make_lineup(
    n_onions: int, n_blemished: int, rng: np.random.Generator
) -> tuple[OnionAppearance, ...]:
    """``n_onions`` appearances, exactly ``n_blemished`` of them blemished, in random order."""
    if isinstance(n_onions, bool) or not isinstance(n_onions, int | np.integer) or n_onions < 1:
        raise ValueError(f"n_onions must be an int >= 1; got {n_onions!r}")
    if (isinstance(n_blemished, bool) or not isinstance(n_blemished, int | np.integer)
            or not 0 <= n_blemished <= n_onions):
        raise ValueError(
            f"n_blemished must be an int in [0, n_onions={n_onions}]; got {n_blemished!r}"
        )
    blemished = np.zeros(n_onions, bool)
    blemished[:n_blemished] = True
    return tuple(sample_appearance(rng, bool(b)) for b in rng.permutation(blemished))


def gate_stop_x(radius: float) -> float:
    """Where on the belt (x) an onion of ``radius`` stops against the raised gate."""
    return _GATE_FACE - radius - 0.002


def in_world(position: np.ndarray) -> bool:
    """Whether a body at ``position`` (3,) is in the world (not parked out of it)."""
    return position[2] > _PARKED[2] / 2


@dataclass
class LineUpOnion:
    """One onion of the line-up: its body and where it is.

    ``place`` is ``"queued"`` (upstream, not yet claimed), ``"waiting"`` (claimed, at the gate),
    ``"held"``, ``"belt"`` (set back on the belt), ``"bin"``, ``"tray"`` or ``"gone"`` (rode
    off the belt); ``perceived`` is the class the station perceived (None until inspected).
    """

    index: int
    body: int
    appearance: OnionAppearance
    position: np.ndarray
    place: str = "queued"
    perceived: Prediction | None = None


class Belt:
    """The line-up's onions in physics client ``client``, queued upstream of the gate.

    Parameters
    ----------
    client : int
        PyBullet physics client id.
    lineup : tuple of OnionAppearance
        The onions in the order they arrive (:func:`make_lineup`).
    lanes : numpy.random.SeedSequence
        Seeds the lane (y) each onion rides in.
    difficulty : Difficulty
        How subtle and one-sided the onions' blemishes are drawn.
    rng : numpy.random.Generator
        Where in the bin a dropped onion lands.
    probe : BlemishProbe, optional
        Registers each onion's texture, to measure the rot a view shows.

    Attributes
    ----------
    onions : list of LineUpOnion
        In line-up order.
    n_claimed : int
        Onions claimed so far (brought to the gate).
    """

    def __init__(self, client: int, lineup: tuple[OnionAppearance, ...], *,
                 lanes: np.random.SeedSequence, difficulty: Difficulty,
                 rng: np.random.Generator, probe: BlemishProbe | None = None) -> None:
        self.client, self.rng = client, rng
        self.onions: list[LineUpOnion] = []
        y = np.random.default_rng(lanes).uniform(*_LANES, len(lineup))
        with tempfile.TemporaryDirectory(prefix="station-onions-") as tmp:
            for i, look in enumerate(lineup):
                tex = onion_texture(look, 64, subtlety=difficulty.blemish_subtlety,
                                    one_sided=difficulty.one_sided_blemish)
                png = save_texture(tex, Path(tmp) / f"{i}.png")
                texture = p.loadTexture(str(png), physicsClientId=client)
                vis = p.createVisualShape(p.GEOM_SPHERE, radius=look.radius,
                                          rgbaColor=[1, 1, 1, 1], physicsClientId=client)
                body = p.createMultiBody(0, -1, vis, basePosition=list(_PARKED),
                                         physicsClientId=client)
                p.changeVisualShape(body, -1, textureUniqueId=texture, physicsClientId=client)
                if probe is not None:
                    probe.add(body, texture, look, 64, subtlety=difficulty.blemish_subtlety,
                              one_sided=difficulty.one_sided_blemish)
                # queued so that at belt travel i * _SPACING it touches the raised gate (the
                # belt starts at travel -_SPACING)
                pos = np.array([gate_stop_x(look.radius) - (i + 1) * _SPACING, y[i],
                                BELT_TOP + look.radius])
                self.onions.append(LineUpOnion(i, body, look, pos))
        self._travel = -_SPACING  # onion k waits at the gate at travel k * _SPACING
        self.n_claimed = 0
        self._in_bin = 0
        self._on_tray = 0

    def put(self, onion: LineUpOnion, position: np.ndarray | None = None) -> None:
        """Show ``onion`` at ``position`` (its own by default) if it is on the belt or in the bin;
        park it out of the world if it is upstream of the belt or has ridden off its end."""
        if position is not None:
            onion.position = np.asarray(position, float).copy()
        x = onion.position[0]
        if onion.place in ("queued", "belt") and x > BELT_HALF_LENGTH - 0.05:
            onion.place = "gone"
        visible = onion.place != "gone" and (
            onion.place != "queued" or x >= -BELT_HALF_LENGTH + 0.05)
        p.resetBasePositionAndOrientation(
            onion.body, onion.position.tolist() if visible else list(_PARKED), [0, 0, 0, 1],
            physicsClientId=self.client)

    def arrange(self) -> None:
        """Show the onions on the belt where they are (park the rest)."""
        for onion in self.onions:
            if onion.place in ("queued", "belt", "waiting"):
                self.put(onion)

    def claim(self) -> LineUpOnion:
        """Run the belt until the next onion of the line-up waits at the raised gate, carrying
        every onion on it downstream (the gate holds none); that onion is claimed."""
        onion = self.onions[self.n_claimed]
        distance = self.n_claimed * _SPACING - self._travel
        self._travel += distance
        for other in self.onions:
            if other.place in ("queued", "belt"):
                other.position[0] += distance
                self.put(other)
        onion.place = "waiting"
        self.n_claimed += 1
        return onion

    def drop_in_bin(self, onion: LineUpOnion) -> None:
        """Put the released ``onion`` in the bin: on the floor or on the onions there, in the
        next slot of a 3 x 3 grid, a little off it."""
        onion.place = "bin"
        slot, layer = self._in_bin % _BIN_SLOTS, min(self._in_bin // _BIN_SLOTS, _BIN_LAYERS - 1)
        self._in_bin += 1
        grid = np.array([slot % 3 - 1, slot // 3 - 1], float) * 0.09
        jitter = self.rng.uniform(-0.015, 0.015, 2)
        floor = BIN_TOP - 0.29  # top of the bin's floor
        self.put(onion, np.array([BIN_CENTER[0] + grid[0] + jitter[0],
                                  BIN_CENTER[1] + grid[1] + jitter[1],
                                  floor + onion.appearance.radius + 0.07 * layer]))

    def set_on_tray(self, onion: LineUpOnion) -> None:
        """Put the released ``onion`` in the next slot of the check tray (rows of six)."""
        onion.place = "tray"
        self.put(onion, _TRAY + np.array([0.09 * (self._on_tray % 6),
                                          0.09 * (self._on_tray // 6),
                                          onion.appearance.radius]))
        self._on_tray += 1

    def position(self, index: int) -> np.ndarray:
        """World position (3,) of line-up onion ``index``, as the physics client has it."""
        body = self.onions[int(index)].body
        pos, _ = p.getBasePositionAndOrientation(body, physicsClientId=self.client)
        return np.array(pos)
