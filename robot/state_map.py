"""The one mapping between the physical world and the onion-sorting MDP state.

Everything that turns an MDP :class:`~irl.domains.onion_sorting.Location` into a place in the
world, or a place in the world back into a location, lives here: the layout of the workcell
(conveyor, bin, the sorter's stance) and the rules that read the state off the world. The
simulator, the Sawyer policy executor and the tests use only these functions.

Coordinates are metres in the PyBullet world frame: ``x`` along the conveyor (the belt moves
towards +x), ``y`` from the conveyor towards the sorter, ``z`` up. Positions have shape (3,).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from irl.domains.onion_sorting import Location, Prediction, SortingState

__all__ = [
    "BELT_HALF_LENGTH",
    "BELT_HALF_WIDTH",
    "BELT_TOP",
    "BIN_CENTER",
    "BIN_HALF_EXTENT",
    "BIN_TOP",
    "HAND_TARGETS",
    "PICK_SPOT",
    "SHOULDER",
    "WorldSnapshot",
    "hand_location",
    "onion_location",
    "state_of_world",
]

BELT_TOP = 0.80
"""Height of the belt's surface."""
BELT_HALF_LENGTH = 1.6
BELT_HALF_WIDTH = 0.15
PICK_SPOT = np.array([0.12, 0.06, BELT_TOP])
"""Where the sorter picks from and places back onto the belt (belt surface)."""
BIN_CENTER = np.array([0.50, 0.32, 0.0])
BIN_HALF_EXTENT = 0.16
BIN_TOP = 0.66
SHOULDER = np.array([0.20, 0.50, 1.38])
"""The sorter's right shoulder."""
FACE_CENTER = np.array([0.0, 0.55, 1.62])

#: Where the sorter's hand goes for each location, shape (3,) each.
HAND_TARGETS: dict[Location, np.ndarray] = {
    Location.CONVEYOR: PICK_SPOT + np.array([0.0, 0.0, 0.09]),
    Location.HOVER: np.array([0.14, 0.22, 1.08]),
    Location.FACE: np.array([0.02, 0.36, 1.50]),
    Location.BIN: np.array([BIN_CENTER[0], BIN_CENTER[1], BIN_TOP + 0.14]),
}

_HAND_TOLERANCE = 0.08


@dataclass(frozen=True)
class WorldSnapshot:
    """What the state is read from: the hand, the onion in focus and the sorter's belief.

    Attributes
    ----------
    hand : ndarray of shape (3,)
        Position of the sorter's hand.
    focus : ndarray of shape (3,) or None
        Position of the onion in focus (claimed, held or just placed); None if none was ever
        claimed.
    held : bool
        Whether the hand holds the onion in focus.
    prediction : Prediction
        What the sorter knows of that onion.
    """

    hand: np.ndarray
    focus: np.ndarray | None
    held: bool
    prediction: Prediction


def in_bin(position: np.ndarray) -> bool:
    """Whether ``position`` (3,) lies inside the bin's footprint, below its rim."""
    p = np.asarray(position, float)
    return bool(
        np.all(np.abs(p[:2] - BIN_CENTER[:2]) <= BIN_HALF_EXTENT) and p[2] <= BIN_TOP + 0.02
    )


def on_belt(position: np.ndarray) -> bool:
    """Whether ``position`` (3,) rests on the belt."""
    p = np.asarray(position, float)
    return bool(
        abs(p[0]) <= BELT_HALF_LENGTH
        and abs(p[1]) <= BELT_HALF_WIDTH
        and BELT_TOP - 0.01 <= p[2] <= BELT_TOP + 0.08
    )


def hand_location(
    hand: np.ndarray, targets: Mapping[Location, np.ndarray] | None = None
) -> Location:
    """The location of the hand: the nearest hand target (within a tolerance).

    ``targets`` maps each location to its target (3,); the human sorter's
    :data:`HAND_TARGETS` by default (the Sawyer station passes its flange targets).

    Raises
    ------
    ValueError
        If the hand is farther than 8 cm from every target (it is between locations).
    """
    hand = np.asarray(hand, float)
    targets = HAND_TARGETS if targets is None else targets
    dists = {loc: float(np.linalg.norm(hand - t)) for loc, t in targets.items()}
    loc = min(dists, key=dists.get)
    if dists[loc] > _HAND_TOLERANCE:
        raise ValueError(
            f"hand must be within {_HAND_TOLERANCE} m of a location; got {hand.round(3).tolist()}, "
            f"{dists[loc]:.3f} m from {loc.name}"
        )
    return loc


def onion_location(position: np.ndarray, held: bool, hand: np.ndarray,
                   targets: Mapping[Location, np.ndarray] | None = None) -> Location:
    """The location of the onion in focus at ``position`` (3,).

    A held onion is where the hand is (HOVER or FACE; see :func:`hand_location` for
    ``targets``); a free one is on the CONVEYOR or in the BIN.
    """
    if held:
        return hand_location(hand, targets)
    if in_bin(position):
        return Location.BIN
    if on_belt(position):
        return Location.CONVEYOR
    raise ValueError(
        f"a free onion must be on the belt or in the bin; got position "
        f"{np.asarray(position).round(3).tolist()}"
    )


def state_of_world(world: WorldSnapshot,
                   targets: Mapping[Location, np.ndarray] | None = None) -> SortingState:
    """Read the MDP state off the physical world (``targets`` as in :func:`hand_location`)."""
    hand = hand_location(world.hand, targets)
    if world.focus is None:
        raise ValueError("world.focus must be a position; got None (no onion was ever claimed)")
    onion = onion_location(world.focus, world.held, world.hand, targets)
    return SortingState(onion, hand, Prediction(world.prediction))
