"""The Sawyer's motion primitives: each :class:`~irl.domains.onion_sorting.SortAction` as the
arm's motions on the station's belt (:mod:`robot.belt`).

- CLAIM raises the gate and runs the belt until the next onion of the line-up waits at the
  pick spot (an indexing belt: it runs only while the station claims; onions placed back
  downstream ride away with it and leave the belt at its end);
- PICK moves above the waiting onion, descends, switches the suction on, lowers the gate and
  lifts the onion to the hover pose;
- INSPECT holds the onion up in front of the inspection camera and shows it from every side:
  the wrist turns it through the inspection poses about its own centre, every other view tilted
  so that its underside faces the camera (:func:`robot.inspection_poses.inspection_poses`),
  the flange at the pose's orientation. Each view is taken with the arm exactly at its pose
  (:meth:`robot.sawyer.Sawyer.snap`) and the onion held as the pick aimed to hold it: a view
  depends on the onion and the pose, never on where the arm came from;
- PLACE_ON_CONVEYOR sets the onion on the belt downstream of the gate, where it rides away (or,
  if it was never inspected, back at the gate, where it waits to be picked again), and returns
  above the pick spot;
- PLACE_IN_BIN moves over the bin and releases the onion, which drops into it.

Deferring an onion (not an action of the MDP) sets it aside on the check tray. The suction grasp
is kinematic (``Sawyer.grasp(body, kinematic=True)``): the held onion's pose is reset to the
flange's after every physics step, and on release it is set down on the belt or dropped to its
place in the bin. Positions are world metres, shape (3,).
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from irl.domains.onion_sorting import Location
from robot.belt import Belt, LineUpOnion, gate_stop_x
from robot.sawyer import Sawyer, flange_down, orientation_angle
from robot.scene import GATE_X, StopGate
from robot.state_map import BELT_TOP, BIN_CENTER, BIN_TOP, PICK_SPOT

__all__ = ["ROBOT_TARGETS", "MotionPrimitives", "target_errors"]

#: Flange (``right_l6``'s frame, :meth:`Sawyer.end_effector`) to the held onion's surface: the
#: link's tool face is 2.45 cm out along the flange's axis, the suction cup 1 cm more.
_GAP = 0.035
_INSPECT_CENTER = np.array([0.02, 0.26, 1.465])  # on the inspection camera's optical axis
_PLACE_X = GATE_X + 0.12  # where the robot sets inspected onions back on the belt

#: Where the Sawyer's flange goes for each location, shape (3,) each; the flange points down.
#: CONVEYOR is above the pick spot; FACE holds the onion on the inspection camera's axis, about
#: 18 cm in front of it; BIN is over the bin's centre, the onion clear of the rim.
ROBOT_TARGETS: dict[Location, np.ndarray] = {
    Location.CONVEYOR: np.array([PICK_SPOT[0], PICK_SPOT[1], BELT_TOP + 0.17]),
    Location.HOVER: np.array([0.14, 0.22, 1.12]),
    Location.FACE: _INSPECT_CENTER + np.array([0.0, 0.0, 0.04 + _GAP]),
    Location.BIN: np.array([BIN_CENTER[0], BIN_CENTER[1], BIN_TOP + 0.16]),
}


def _above(point: np.ndarray) -> np.ndarray:
    return np.array([point[0], point[1], ROBOT_TARGETS[Location.CONVEYOR][2]])


def target_errors(arm: Sawyer) -> dict[Location, tuple[float, float]]:
    """IK accuracy of ``arm`` at each flange target of :data:`ROBOT_TARGETS`:
    ``location -> (position error m, angle error rad)``. The arm is left where it was."""
    start = arm.q
    errors = {}
    down = flange_down(0.0)
    for loc, target in ROBOT_TARGETS.items():
        arm.reset(arm.solve(target))
        pos, orn = arm.end_effector()
        errors[loc] = (float(np.linalg.norm(pos - target)), orientation_angle(orn, down))
    arm.reset(start)
    return errors


class MotionPrimitives:
    """The Sawyer's motions for each action, on the onions of ``belt``.

    PICK, INSPECT and the PLACEs return the final flange position error (m) of each of their
    arm motions.

    Parameters
    ----------
    arm : Sawyer
        The arm, its :attr:`~robot.sawyer.Sawyer.rest` the configuration above the pick spot.
    belt : Belt
    gate : StopGate
    move_steps : int
        Physics steps per arm motion (half of them for the short ones).
    """

    def __init__(self, arm: Sawyer, belt: Belt, gate: StopGate, move_steps: int) -> None:
        self.arm, self.belt, self.gate, self.move_steps = arm, belt, gate, move_steps

    def move(self, target: np.ndarray, steps: int | None = None, *,
             orientation: tuple[float, ...] | None = None,
             seed: np.ndarray | None = None) -> float:
        """:meth:`robot.sawyer.Sawyer.reach` ``target`` in ``steps`` physics steps (by default
        ``move_steps``)."""
        return self.arm.reach(target, steps or self.move_steps, orientation=orientation,
                              seed=seed)

    def claim(self) -> LineUpOnion:
        """Raise the gate and bring the next onion of the line-up to it; returns the onion.

        Raises
        ------
        RuntimeError
            If every onion of the line-up was claimed.
        """
        if self.belt.n_claimed >= len(self.belt.onions):
            raise RuntimeError(
                f"the line-up is exhausted: all {len(self.belt.onions)} onions were claimed"
            )
        self.gate.set(True)
        return self.belt.claim()

    def pick(self, onion: LineUpOnion) -> list[float]:
        errs = []
        grip = onion.position + np.array([0.0, 0.0, onion.appearance.radius + _GAP])
        if np.linalg.norm(self.arm.end_effector()[0] - _above(grip)) > 0.01:
            errs.append(self.move(_above(grip)))
        errs.append(self.move(grip, self.move_steps // 2))
        self.arm.grasp(onion.body, kinematic=True, flange=(grip, flange_down(0.0)))
        onion.place = "held"
        self.gate.set(False)
        errs.append(self.move(_above(grip), self.move_steps // 2))
        errs.append(self.move(ROBOT_TARGETS[Location.HOVER]))
        return errs

    def hold_up(self) -> list[float]:
        """Bring the held onion to the inspection pose, in front of the inspection camera."""
        return [self.move(ROBOT_TARGETS[Location.FACE])]

    def show(self, onion: LineUpOnion, poses: tuple[tuple[float, float], ...],
             errs: list[float]) -> Iterator[int]:
        """Show the held ``onion``, at the inspection pose (:meth:`hold_up`), from every side.

        The wrist turns (and tilts) it through ``poses`` ``(yaw, tilt)`` about its own centre;
        yields ``k`` with the arm exactly at the ``k``-th pose (:meth:`Sawyer.snap
        <robot.sawyer.Sawyer.snap>`). Each turned pose is solved from the inspection pose's own
        solution with the wrist already turned by the pose's yaw
        (:meth:`Sawyer.wrist_turns <robot.sawyer.Sawyer.wrist_turns>`), so that the view is the
        one designed, whatever the views before it. Once closed, or past the last pose, it
        brings the onion back to the inspection pose. The motions' errors go to ``errs``.
        """
        self.arm.snap()
        face = self.arm.goal  # the inspection pose's solution, solved from the arm's rest
        centre = self.belt.position(onion.index)
        shown = 0
        try:
            for k, (yaw, tilt) in enumerate(poses):
                if k:
                    turn = flange_down(yaw, tilt)
                    errs.append(self.move(self.arm.flange_holding_at(centre, turn),
                                          self.move_steps // 2, orientation=turn,
                                          seed=self.arm.wrist_turns(face, yaw)))
                    self.arm.snap()
                shown += 1
                yield k
        finally:
            if shown > 1:
                errs.append(self.move(ROBOT_TARGETS[Location.FACE], self.move_steps // 2,
                                      seed=face))

    def place_on_conveyor(self, onion: LineUpOnion) -> list[float]:
        inspected = onion.perceived is not None
        r = onion.appearance.radius
        # an inspected onion goes downstream of the gate and rides away; an uninspected one
        # stays in focus: it goes back to the gate, which rises again
        x = _PLACE_X if inspected else gate_stop_x(r)
        rest = np.array([x, onion.position[1], BELT_TOP + r])
        grip = rest + np.array([0.0, 0.0, r + _GAP])
        errs = [self.move(_above(grip)), self.move(grip, self.move_steps // 2)]
        self.arm.release()
        onion.place = "belt" if inspected else "waiting"
        self.gate.set(not inspected)
        self.belt.put(onion, rest)
        errs.append(self.move(_above(grip), self.move_steps // 2))
        errs.append(self.move(ROBOT_TARGETS[Location.CONVEYOR], self.move_steps // 2))
        return errs

    def place_in_bin(self, onion: LineUpOnion) -> list[float]:
        errs = [self.move(ROBOT_TARGETS[Location.BIN])]
        self.arm.release()
        self.belt.drop_in_bin(onion)
        return errs

    def set_aside(self, onion: LineUpOnion) -> None:
        """Put ``onion`` (picked first if not held) on the check tray, and go back above the
        pick spot with the gate raised."""
        if onion.place != "held":
            self.pick(onion)
        self.move(ROBOT_TARGETS[Location.HOVER])
        self.arm.release()
        self.belt.set_on_tray(onion)
        self.gate.set(True)
        self.move(ROBOT_TARGETS[Location.CONVEYOR], self.move_steps // 2)
