"""A line-up recorded once, replayed as a sorting cell: P/R of any policy without the arm.

A lab records its robot inspecting a line of onions once, every view of every onion. Replayed
here, the recorded views stand in for the arm: each onion the policy inspects shows the views
the recording holds of it, each action moves the onion and the gripper as the MDP says
(:func:`irl.domains.onion_sorting.next_state`), and the policy's place decision gives the
onion's fate. So methods compare on the lab's own onions without running its arm once each.

Because every onion's views are the same whichever policy runs (:mod:`robot.station`), a line-up
recorded from the simulated Sawyer and replayed here gives the same fates as the live run of
the same policy on the same seed. Reading the recording (image files, CSV) is the caller's: it
hands over a function from an onion's line-up index to its views.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from irl.domains.onion_sorting import Prediction, SortAction, SortingState, next_state
from robot.cell import START_STATE, Read
from robot.tally import Fate

__all__ = ["ReplayedLineup"]


class ReplayedLineup:
    """A recorded line-up as a :class:`robot.cell.SortingCell`.

    Parameters
    ----------
    n_onions : int
        The line-up's size; its onions are claimed in order, 0 first.
    views : callable
        ``views(index)``: the recorded views of onion ``index``, each (h, w, 3) uint8 RGB, in
        the order the robot showed them (loaded when the policy first inspects it).
    """

    def __init__(self, n_onions: int, views: Callable[[int], Sequence[np.ndarray]]) -> None:
        if isinstance(n_onions, bool) or not isinstance(n_onions, int | np.integer) \
                or n_onions < 1:
            raise ValueError(f"n_onions must be an int >= 1; got {n_onions!r}")
        if not callable(views):
            raise TypeError(f"views must be a callable index -> views; got "
                            f"{type(views).__name__}")
        self.n_onions = int(n_onions)
        self._views = views
        self._state = START_STATE
        self._focus: int | None = None
        self._claimed = 0
        self._calls: dict[int, Prediction] = {}
        self._fates: list[Fate | None] = [None] * self.n_onions

    @property
    def state(self) -> SortingState:
        """The state the actions so far led to."""
        return self._state

    @property
    def focus(self) -> int | None:
        """The onion in focus (the last claimed), None before the first claim and after a
        deferral."""
        return self._focus

    def fate(self, index: int) -> Fate | None:
        """What the policy decided for onion ``index`` (None while undecided)."""
        return self._fates[int(index)]

    def _require_focus(self, what: str) -> int:
        if self._focus is None:
            raise RuntimeError(f"no onion is in focus to {what}")
        return self._focus

    def execute(self, action: SortAction | int) -> None:
        """Move the onion and the gripper as the MDP says; a place decides the onion's fate
        (an uninspected onion set back on the line waits to be picked again).

        Raises
        ------
        ValueError
            If ``action`` is INSPECT (:meth:`inspect`).
        RuntimeError
            If a CLAIM finds every onion claimed, or another action finds none in focus.
        """
        a = SortAction(int(action))
        if a == SortAction.INSPECT:
            raise ValueError("INSPECT reads the views: call inspect(read)")
        if a == SortAction.CLAIM:
            if self._claimed >= self.n_onions:
                raise RuntimeError(f"the line-up is exhausted: all {self.n_onions} onions were "
                                   "claimed")
            self._focus, self._claimed = self._claimed, self._claimed + 1
        else:
            onion = self._require_focus(a.name)
            inspected = self._state.prediction != Prediction.UNKNOWN
            if a == SortAction.PLACE_IN_BIN:
                self._fates[onion] = "bin"
            elif a == SortAction.PLACE_ON_CONVEYOR and inspected:
                self._fates[onion] = "line"
        self._state = next_state(self._state, a, blemished=False)

    def inspect(self, read: Read) -> None:
        """Show the recorded views of the onion in focus to ``read`` (the first time) and keep
        its call.

        Raises
        ------
        RuntimeError
            If no onion is in focus.
        """
        onion = self._require_focus("inspect")
        if onion not in self._calls:
            self._calls[onion] = Prediction(int(read(iter(self._views(onion)))))
        self._state = next_state(self._state, SortAction.INSPECT,
                                 blemished=self._calls[onion] == Prediction.BAD)

    def defer(self) -> int:
        """Hand the onion in focus to a person (fate ``"tray"``); returns its index.

        Raises
        ------
        RuntimeError
            If no onion is in focus.
        """
        onion = self._require_focus("defer")
        self._fates[onion] = "tray"
        self._focus, self._state = None, START_STATE
        return onion
