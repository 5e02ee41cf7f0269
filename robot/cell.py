"""One sorting loop for any robot: the cell it drives, and the loop.

A *cell* is whatever sorts the onions: the simulated Sawyer (:class:`robot.station.
SawyerStation`), a line-up recorded once and replayed (:class:`robot.replay.ReplayedLineup`),
or a lab's own arm. It satisfies :class:`SortingCell`, a small :class:`typing.Protocol`: its
state, executing an action, showing the onion in hand to the inspection camera view by view,
deferring an onion to a person, and what happened to each onion. Nothing else of the robot is
needed: the loop (:class:`SortingRun`) reads the state, asks the greedy policy ``actions[s]``
(48,) for an action (:func:`greedy_actions`), defers where it is unsure (:func:`confidence_in`),
reads the views into a call (:class:`ViewReader`) and counts every fate
(:class:`robot.tally.SortingTally`). It imports no simulator.

An action the MDP says does nothing in the current state (``next_state(s, a) == s``) is not
sent to the cell (it still spends a step). After every action the cell's state must equal
``next_state(s, a, blemished=<the call on the onion in focus>)``: the prediction factor is what
the robot *perceived*, so perception errors propagate exactly as in the MDP.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Literal, Protocol, runtime_checkable

import numpy as np

from irl.domains.onion_sorting import (
    N_ACTIONS,
    N_STATES,
    Location,
    Prediction,
    SortAction,
    SortingState,
    encode_state,
    next_state,
)
from robot.classifier import (
    GROUND_TRUTH,
    Classifier,
    SequentialClassifier,
    check_classifier,
    read_answer,
)
from robot.tally import Fate, SortingResult, SortingTally

__all__ = [
    "START_STATE",
    "CellStep",
    "Read",
    "Reading",
    "SortingCell",
    "SortingRun",
    "ViewReader",
    "confidence_in",
    "greedy_actions",
    "take_action",
]

logger = logging.getLogger(__name__)

START_STATE = SortingState(Location.CONVEYOR, Location.CONVEYOR, Prediction.GOOD)
"""A cell's first state: the MDP's initial state with nothing in focus (as if an onion had just
been left on the line). The policy must CLAIM; a cell is in it again after deferring."""

Read = Callable[[Iterable[np.ndarray]], Prediction]
"""``read(views) -> call``: what a cell hands the views of the onion in hand to, one at a time
as it shows them (each (h, w, 3) uint8 RGB); it stops taking them once the call is settled."""


@runtime_checkable
class SortingCell(Protocol):
    """A robot that sorts a line-up of onions, as the sorting loop drives it.

    Onions are numbered by their place in the line-up, from 0, in the order the robot claims
    them. A lab's arm satisfies it with one class (docs/robot.md shows one for a ROS 2 arm).
    """

    @property
    def state(self) -> SortingState:
        """Where the onion in focus and the gripper are, and the call on that onion
        (``Prediction.UNKNOWN`` until inspected); :data:`START_STATE` before the first claim
        and after a deferral."""
        ...

    @property
    def focus(self) -> int | None:
        """The line-up index of the onion in focus (the last claimed); None before the first
        claim and after a deferral."""
        ...

    def execute(self, action: SortAction) -> None:
        """Carry out ``action`` (CLAIM, PICK, PLACE_ON_CONVEYOR or PLACE_IN_BIN), which the
        MDP says changes the state. PLACE_ON_CONVEYOR sets an inspected onion on the line,
        where it rides away, and an uninspected one back where it was claimed."""
        ...

    def inspect(self, read: Read) -> None:
        """INSPECT: hold the onion in hand up to the inspection camera. The first time, show it
        side by side, handing its views to ``read`` (a generator is best: ``read`` stops taking
        views once the call is settled) and keep the call it returns, which :attr:`state`
        reports from then on; an onion inspected before is only held up again."""
        ...

    def defer(self) -> int:
        """Set the onion in focus aside for a person (its fate ``"tray"``); nothing is in
        focus afterwards. Returns its line-up index."""
        ...

    def fate(self, index: int) -> Fate | None:
        """What became of onion ``index``: ``"bin"``, ``"line"`` (set back on the line after
        inspection), ``"tray"`` (deferred), or None while undecided."""
        ...


_CELL_MEMBERS = ("state", "focus", "execute", "inspect", "defer", "fate")


def greedy_actions(actions: np.ndarray) -> np.ndarray:
    """The greedy policy ``actions[s]`` (48,) int of ``actions`` (48,) or ``pi[s, a]`` (48, 5).

    Raises
    ------
    ValueError
        If ``actions`` has another shape, non-integer or out-of-range action indices, or
        non-finite probabilities.
    """
    arr = np.asarray(actions)
    if arr.shape == (N_STATES, N_ACTIONS):
        if not np.issubdtype(arr.dtype, np.number) or not np.all(np.isfinite(arr)):
            raise ValueError(f"actions as pi[s, a] must be finite numbers; got dtype "
                             f"{arr.dtype}")
        return np.argmax(arr, axis=1).astype(np.int64)
    if arr.shape != (N_STATES,):
        raise ValueError(
            f"actions must be an action index per state, shape ({N_STATES},), or a policy "
            f"pi[s, a] of shape ({N_STATES}, {N_ACTIONS}); got shape {arr.shape}"
        )
    if arr.dtype == bool or not np.issubdtype(arr.dtype, np.number):
        raise ValueError(f"actions must hold integer action indices; got dtype {arr.dtype}")
    if not np.all(np.isfinite(arr)) or not np.all(arr == np.round(arr)):
        raise ValueError("actions must hold integer action indices; got non-integer values")
    if arr.min() < 0 or arr.max() >= N_ACTIONS:
        raise ValueError(f"actions must be action indices in [0, {N_ACTIONS}); got values in "
                         f"[{arr.min()}, {arr.max()}]")
    return arr.astype(np.int64)


def check_confidence(confidence: np.ndarray | None) -> np.ndarray | None:
    """``confidence`` as a float array of shape (48,) or (48, 5) with values in [0, 1].

    Raises
    ------
    ValueError
        If it has another shape or a value outside [0, 1].
    """
    if confidence is None:
        return None
    conf = np.asarray(confidence, float)
    if conf.shape not in ((N_STATES,), (N_STATES, N_ACTIONS)) \
            or not np.all((conf >= 0) & (conf <= 1)):
        raise ValueError(f"confidence must hold values in [0, 1], one per state ({N_STATES}) "
                         f"or per state and action ({N_STATES}, {N_ACTIONS}); got shape "
                         f"{conf.shape}")
    return conf


def confidence_in(confidence: np.ndarray, state: SortingState, action: int,
                  p_blemished: float | None = None) -> float:
    """How sure the robot is that ``action`` is right in the state it perceives.

    ``confidence[s, a]`` (48, 5) is the share of the posterior's reward samples whose greedy
    policy takes ``a`` in ``s``. Where the onion in focus has been inspected (the state says
    good or blemished) and the inspection gave ``p_blemished``, the state itself is uncertain:
    the confidence is that of ``action`` in the state with a good onion and in the state with a
    blemished one, weighed by ``1 - p_blemished`` and ``p_blemished`` (the probability that the
    action is the best one, given the demonstrations and what the robot saw). Elsewhere, or
    with no probability, it is ``confidence[s, action]``. A ``confidence[s]`` (48,) is the
    policy's own action's share, read as it is.
    """
    s = encode_state(state)
    if confidence.ndim == 1:
        return float(confidence[s])
    if p_blemished is None or state.prediction == Prediction.UNKNOWN:
        return float(confidence[s, action])
    good = encode_state(state._replace(prediction=Prediction.GOOD))
    bad = encode_state(state._replace(prediction=Prediction.BAD))
    return float((1.0 - p_blemished) * confidence[good, action]
                 + p_blemished * confidence[bad, action])


@dataclass(frozen=True)
class Reading:
    """What the inspection of one onion found.

    Attributes
    ----------
    call : Prediction
        GOOD or BAD (an onion no view showed counts as GOOD).
    views : tuple of ndarray of shape (h, w, 3)
        The views read, in the order shown.
    p_blemished : float or None
        The classifier's fused probability that the onion is blemished, where it gave one.
    view_p_blemished : tuple of (float or None)
        Each view's, where it gave them (None: no onion found).
    """

    call: Prediction
    views: tuple[np.ndarray, ...] = field(repr=False)
    p_blemished: float | None = None
    view_p_blemished: tuple[float | None, ...] = field(default=(), repr=False)


class ViewReader:
    """Reads the views of an onion into a call, as the robot shows them.

    Parameters
    ----------
    classify : callable or "ground-truth"
        ``classify(views) -> Prediction or Verdict`` (:data:`robot.classifier.Classifier`);
        a :class:`~robot.classifier.SequentialClassifier` reads each view as it comes.
        ``"ground-truth"`` calls each onion's true class (the views are still taken).
    max_views : int
        The most views it takes of an onion.
    stop_when_settled : bool
        With a sequential classifier, stop taking views once the call can no longer change
        (under ``noisy-or``, a view that shows rot settles a blemish at once): the call all
        ``max_views`` views would give, from fewer. False: take every view shown.
    """

    def __init__(self, classify: Classifier | Literal["ground-truth"], *, max_views: int,
                 stop_when_settled: bool = True) -> None:
        check_classifier(classify)
        if isinstance(max_views, bool) or not isinstance(max_views, int | np.integer) \
                or max_views < 1:
            raise ValueError(f"max_views must be an int >= 1; got {max_views!r}")
        self.classify = classify
        self.max_views = int(max_views)
        self.stop_when_settled = bool(stop_when_settled)

    def read(self, views: Iterable[np.ndarray], blemished: bool | None = None
             ) -> Reading | None:
        """The reading of the views ``views`` of one onion, taken one at a time (at most
        :attr:`max_views`); None if it was shown none. ``blemished`` is the onion's true class,
        which ground-truth inspection needs.

        Raises
        ------
        ValueError
            If the classifier's answer is not a Prediction or a verdict with one, or
            ground-truth inspection is asked of an onion whose class is unknown.
        """
        if self.classify == GROUND_TRUTH and blemished is None:
            raise ValueError("ground-truth inspection needs each onion's true class; this "
                             "line-up has none")
        sequential = isinstance(self.classify, SequentialClassifier)
        taken: list[np.ndarray] = []
        view_p: list[float | None] = []
        for k, view in enumerate(views):
            taken.append(np.asarray(view))
            if sequential:
                view_p.extend(self.classify.view_probabilities([taken[-1]]))
                if self.stop_when_settled and self.classify.settled(
                        view_p, self.max_views - k - 1):
                    break
            if len(taken) == self.max_views:
                break
        if not taken:
            return None
        call, p_bad, per_view = read_answer(self.classify, bool(blemished), taken,
                                            view_p if sequential else None)
        if call is None:
            logger.warning("the classifier abstained on all %d views of an onion; it counts "
                           "as GOOD", len(taken))
            call = Prediction.GOOD
        return Reading(call, tuple(taken), p_bad, per_view)


@dataclass(frozen=True)
class CellStep:
    """What one action did.

    Attributes
    ----------
    state, next_state : SortingState
        The cell's state before and after.
    action : SortAction
    onion : int or None
        Line-up index of the onion in focus after the action (None before the first claim).
    reading : Reading or None
        What the inspection found, if this action inspected an onion.
    """

    state: SortingState
    action: SortAction
    next_state: SortingState
    onion: int | None
    reading: Reading | None = None

    @property
    def changed(self) -> bool:
        """Whether the action did anything (``next_state != state``)."""
        return self.next_state != self.state

    @property
    def perceived(self) -> Prediction | None:
        """The inspection's call, if this action inspected an onion."""
        return None if self.reading is None else self.reading.call

    @property
    def views(self) -> tuple[np.ndarray, ...]:
        """The views the inspection read (empty if this action inspected none)."""
        return () if self.reading is None else self.reading.views

    @property
    def p_blemished(self) -> float | None:
        """The inspection's probability of a blemish, where it gave one."""
        return None if self.reading is None else self.reading.p_blemished

    @property
    def view_p_blemished(self) -> tuple[float | None, ...]:
        """Each view's probability of a blemish, where the classifier gave them."""
        return () if self.reading is None else self.reading.view_p_blemished


def take_action(cell: SortingCell, action: SortAction | int, reader: ViewReader,
                truth: np.ndarray | None = None) -> CellStep:
    """Execute one action on ``cell`` and check that it reached the MDP's next state.

    Parameters
    ----------
    cell : SortingCell
    action : SortAction or int
    reader : ViewReader
        Reads the views if the action inspects an onion.
    truth : ndarray of shape (n_onions,), optional
        The line-up's true classes (ground-truth inspection reads them).

    Raises
    ------
    ValueError
        If ``action`` is not a :class:`SortAction`.
    RuntimeError
        If the cell's state afterwards is not ``next_state(s, a, blemished=<the call>)``.
    """
    try:
        a = SortAction(int(action))
    except (TypeError, ValueError):
        raise ValueError(
            f"action must be a SortAction in [0, {len(SortAction)}); got {action!r}"
        ) from None
    s = cell.state
    applies = next_state(s, a, blemished=False) != s or next_state(s, a, blemished=True) != s
    reading = None
    if applies and a == SortAction.INSPECT:
        onion = cell.focus
        found: list[Reading] = []

        def read(views: Iterable[np.ndarray]) -> Prediction:
            taken = reader.read(views, None if truth is None or onion is None
                                else bool(truth[onion]))
            if taken is None:
                raise RuntimeError(f"the cell showed no view of onion {onion} to inspect")
            found.append(taken)
            return taken.call

        cell.inspect(read)
        reading = found[-1] if found else None
    elif applies:
        cell.execute(a)
    seen = cell.state
    # only a first inspection's next state depends on the class: the call it read
    expected = next_state(s, a, blemished=reading is not None
                          and reading.call == Prediction.BAD)
    if seen != expected:
        raise RuntimeError(f"after {a.name} in {s} the cell shows {seen}; the MDP says "
                           f"{expected}")
    logger.debug("%s: %s -> %s", a.name, s, seen)
    return CellStep(state=s, action=a, next_state=seen, onion=cell.focus, reading=reading)


class SortingRun:
    """A greedy policy sorting a line-up on a cell: the sorting loop, one action at a time.

    :meth:`run` is the loop; :meth:`act` one action of it (the Gymnasium environment steps
    through it so).

    Parameters
    ----------
    cell : SortingCell
    n_onions : int
        The line-up's size.
    reader : ViewReader
        Reads each inspected onion's views into a call.
    truth : ndarray of shape (n_onions,), optional
        The line-up's true classes: the running counts and :meth:`result` need them (a lab's
        arm has none: score its tally with the truth afterwards, ``onionsort score``).
    max_steps_per_onion : int
        The episode's step budget is ``n_onions * max_steps_per_onion`` actions.
    confidence : ndarray of shape (48, 5) or (48,), optional
        How sure the policy is of each action in each state, or of its own; with
        ``defer_below``, where the confidence in the next action (:func:`confidence_in`) is
        below it, the onion in focus is deferred (:meth:`SortingCell.defer`) instead.
    defer_below : float
        0 never defers.

    Attributes
    ----------
    tally : SortingTally
    n_steps : int
        Actions taken so far (deferrals are no action of the MDP).
    """

    def __init__(self, cell: SortingCell, n_onions: int, reader: ViewReader, *,
                 truth: np.ndarray | None = None, max_steps_per_onion: int = 12,
                 confidence: np.ndarray | None = None, defer_below: float = 0.0) -> None:
        missing = [name for name in _CELL_MEMBERS if not hasattr(type(cell), name)
                   and name not in getattr(cell, "__dict__", {})]  # no property is run
        if missing:
            raise TypeError(f"cell must be a SortingCell ({', '.join(_CELL_MEMBERS)}); "
                            f"{type(cell).__name__} has no {', '.join(missing)}")
        if isinstance(max_steps_per_onion, bool) \
                or not isinstance(max_steps_per_onion, int | np.integer) \
                or max_steps_per_onion < 1:
            raise ValueError(f"max_steps_per_onion must be an int >= 1; got "
                             f"{max_steps_per_onion!r}")
        if isinstance(defer_below, bool) or not isinstance(defer_below, int | float) \
                or not 0.0 <= defer_below <= 1.0:
            raise ValueError(f"defer_below must be in [0, 1]; got {defer_below!r}")
        self.cell, self.reader = cell, reader
        self.tally = SortingTally(n_onions, truth)
        self.truth = None if truth is None else np.asarray(truth, bool)
        self.budget = self.tally.n_onions * int(max_steps_per_onion)
        self.confidence = check_confidence(confidence)
        self.defer_below = float(defer_below)
        self.n_steps = 0

    @property
    def over(self) -> bool:
        """Whether the episode is over: every onion has a fate, or the budget is spent."""
        return self.tally.complete or self.n_steps >= self.budget

    def unsure(self, action: SortAction | int) -> bool:
        """Whether the robot is too unsure of ``action`` in the cell's state to take it: the
        onion in focus, undecided, then goes to a person."""
        focus = self.cell.focus
        if self.confidence is None or focus is None or self.tally.fates[focus] is not None:
            return False
        return confidence_in(self.confidence, self.cell.state, int(action),
                             self.tally.p_blemished.get(focus)) < self.defer_below

    def defer(self) -> int:
        """Defer the onion in focus to a person; returns its line-up index.

        Raises
        ------
        RuntimeError
            If the cell does not then report it on the tray.
        """
        index = self.cell.defer()
        fate = self.cell.fate(index)
        if fate != "tray":
            raise RuntimeError(f"the cell deferred onion {index} but reports its fate as "
                               f"{fate!r}, not 'tray'")
        self.tally.decide(index, fate)
        return index

    def act(self, action: SortAction | int) -> tuple[CellStep, Fate | None]:
        """Take one action; returns what it did and the fate it gave the onion in focus (None
        if it gave none)."""
        done = take_action(self.cell, action, self.reader, self.truth)
        self.n_steps += 1
        if done.reading is not None:
            self.tally.inspected(done.onion, done.reading.call, done.reading.p_blemished,
                                 len(done.reading.views))
        fate = None
        if done.changed and done.onion is not None:
            now = self.cell.fate(done.onion)
            if now is not None and self.tally.decide(done.onion, now):
                fate = now
        return done, fate

    def run(self, actions: np.ndarray,
            on_step: Callable[[CellStep, Fate | None], None] | None = None) -> SortingTally:
        """Sort until every onion has a fate or the budget is spent, taking the greedy
        action ``actions[s]`` (48,) (or the argmax of ``pi[s, a]`` (48, 5)) in each state;
        ``on_step(step, fate)`` after every action. Returns the tally."""
        policy = greedy_actions(actions)
        while not self.over:
            a = SortAction(int(policy[encode_state(self.cell.state)]))
            if self.unsure(a):
                self.defer()  # not an action of the MDP: no step counted
                continue
            done, fate = self.act(a)
            if on_step is not None:
                on_step(done, fate)
        return self.tally

    def result(self) -> SortingResult:
        """The episode's result (:meth:`robot.tally.SortingTally.result`); needs the truth."""
        return self.tally.result(self.n_steps)
