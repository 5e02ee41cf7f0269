"""The sorting evaluation: the Sawyer executes a greedy policy on a line-up of onions.

Policies are ``actions[s]`` (48,) — an action index per state index of
:mod:`irl.domains.onion_sorting` — or ``pi[s, a]`` (48, 5), whose argmax is taken.

Each onion of the line-up ends with a *fate*: ``"bin"`` if the robot placed it in the bin,
``"line"`` if it set it back on the belt after inspecting it (it rides away). The episode starts
in :data:`robot.station.START_STATE` (the MDP's initial state, nothing claimed yet) and ends
when every onion has a fate or the step budget ``n_onions * max_steps_per_onion`` is spent;
onions still undecided then (never claimed, or claimed and not yet released for good) count as
left on the line. With a confidence and ``defer_below``, the robot defers where it is less sure
than the threshold that its next action is right (:func:`confidence_in`: the policy's
confidence, weighed over what an inspected onion may be): the onion in focus goes to a check
tray for a person (fate ``"tray"``) and is counted apart, in ``deferred``; precision and recall
are over the onions it sorted. With blemished onions the positive class:

=====  ==============================  =====  ==============================
TP     blemished onion in the bin      FP     good onion in the bin
FN     blemished onion left on line    TN     good onion left on the line
=====  ==============================  =====  ==============================

``precision = TP / (TP + FP)`` and ``recall = TP / (TP + FN)``; a ratio with a zero denominator
(nothing binned; no blemished onion) is defined as 0.0, as scikit-learn's
``zero_division=0``.

For logging and recording, :func:`evaluate_policy` reports the station at rest before the first
action (``on_start``, a :class:`StationView`) and after every action (``on_step``, an
:class:`EvaluationStep`: the decision, the running counts and the same view): the camera's
images when rendering, the onions in the world, a snapshot of the world in 3D
(:class:`robot.world.WorldState`) and the joints.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from irl.domains.onion_sorting import (
    N_ACTIONS,
    N_STATES,
    Prediction,
    SortAction,
    SortingState,
    encode_state,
)
from robot.classifier import Classifier
from robot.difficulty import Difficulty
from robot.labels import OnionLabel
from robot.station import INSPECTION_VIEWS, STEP_DURATION_S, SawyerStation, StationStep
from robot.world import WorldState

__all__ = [
    "EvaluationStep",
    "OnionOutcome",
    "SortingResult",
    "SortingTally",
    "StationView",
    "confidence_in",
    "evaluate_policy",
    "greedy_actions",
]

logger = logging.getLogger(__name__)

Fate = Literal["bin", "line", "tray"]


@dataclass(frozen=True)
class OnionOutcome:
    """What happened to one onion of the line-up.

    Attributes
    ----------
    index : int
        Position in the line-up.
    blemished : bool
        Its true class.
    perceived : Prediction or None
        What the classifier said when the robot inspected it (None if never inspected).
    fate : {"bin", "line", "tray"}
        Where it ended; undecided onions count as ``"line"``; ``"tray"`` if the robot deferred
        it to a person.
    decided : bool
        False if the episode ended before the robot released it for good (or claimed it).
    p_blemished : float or None
        The inspection's probability that it is blemished, where the classifier gave one.
    views : int
        Inspection views the robot took of it (0 if never inspected).
    """

    index: int
    blemished: bool
    perceived: Prediction | None
    fate: Fate
    decided: bool = True
    p_blemished: float | None = None
    views: int = 0

    def to_dict(self) -> dict:
        return {
            "index": self.index, "blemished": self.blemished,
            "perceived": None if self.perceived is None else self.perceived.name.lower(),
            "p_blemished": None if self.p_blemished is None else round(self.p_blemished, 5),
            "fate": self.fate, "decided": self.decided, "views": self.views,
        }


def _ratio(num: int, den: int) -> float:
    return num / den if den else 0.0


class _PrecisionRecall:
    """``precision`` and ``recall`` of a class with ``tp``, ``fp`` and ``fn`` counts."""

    tp: int
    fp: int
    fn: int

    @property
    def precision(self) -> float:
        """``TP / (TP + FP)``; 0.0 while nothing is binned."""
        return _ratio(self.tp, self.tp + self.fp)

    @property
    def recall(self) -> float:
        """``TP / (TP + FN)``; 0.0 while no blemished onion is decided."""
        return _ratio(self.tp, self.tp + self.fn)


@dataclass(frozen=True)
class SortingResult(_PrecisionRecall):
    """The outcome of one evaluation episode (see the module docstring for the counts)."""

    tp: int
    fp: int
    tn: int
    fn: int
    n_steps: int
    undecided: int
    onions: tuple[OnionOutcome, ...] = field(repr=False)
    deferred: int = 0

    def __post_init__(self) -> None:
        if self.tp + self.fp + self.tn + self.fn + self.deferred != len(self.onions):
            raise ValueError(
                f"tp + fp + tn + fn + deferred must equal the number of onions "
                f"{len(self.onions)}; got {self.tp} + {self.fp} + {self.tn} + {self.fn} + "
                f"{self.deferred}"
            )

    @property
    def deferral_rate(self) -> float:
        """The share of the line-up deferred to a person."""
        return _ratio(self.deferred, len(self.onions))

    def to_dict(self) -> dict:
        """A JSON-ready dict: counts, precision, recall, steps, the inspection views taken and
        the per-onion outcomes."""
        return {
            "tp": self.tp, "fp": self.fp, "tn": self.tn, "fn": self.fn,
            "precision": self.precision, "recall": self.recall,
            "n_onions": len(self.onions), "n_steps": self.n_steps, "undecided": self.undecided,
            "deferred": self.deferred, "deferral_rate": self.deferral_rate,
            "views_taken": self.views_taken, "onions": [o.to_dict() for o in self.onions],
        }

    @property
    def views_taken(self) -> int:
        """Inspection views the robot took in all."""
        return sum(o.views for o in self.onions)

    def table(self) -> str:
        """The confusion table with precision and recall, as aligned text."""
        rows = [
            f"{'':>15} {'in bin':>8} {'on line':>8}",
            f"{'blemished':>15} {'TP ' + str(self.tp):>8} {'FN ' + str(self.fn):>8}",
            f"{'good':>15} {'FP ' + str(self.fp):>8} {'TN ' + str(self.tn):>8}",
            f"precision {self.precision:.3f}   recall {self.recall:.3f}   "
            f"({len(self.onions)} onions, {self.n_steps} steps, {self.undecided} undecided)",
        ]
        if self.deferred:
            rows.append(f"deferred to a person: {self.deferred} "
                        f"(rate {self.deferral_rate:.3f}; not in the counts above)")
        return "\n".join(rows)


@dataclass(frozen=True)
class EvaluationStep(_PrecisionRecall):
    """One action of the evaluation, for logging (:func:`evaluate_policy`'s ``on_step``).

    Attributes
    ----------
    step : int
        Action number in the episode (from 0).
    state, action, next_state : int
        Flat state index, action index and next flat state index.
    onion : int or None
        Line-up index of the onion in focus after the action.
    blemished : bool or None
        Its true class.
    perceived : Prediction or None
        The classifier's answer, if this action inspected the onion.
    fate : {"bin", "line"} or None
        The onion's fate, if this action decided it.
    tp, fp, tn, fn : int
        Running counts over the onions decided so far.
    color : ndarray of shape (H, W, 3) or None
        uint8 RGB of the main camera after the action (when rendering).
    depth : ndarray of shape (H, W) or None
        float32 depth in metres of the main camera (when rendering).
    inspection : ndarray of shape (h, w, 3) or None
        uint8 RGB of the first inspection view, if this action inspected the onion.
    views : tuple of ndarray of shape (h, w, 3)
        Every inspection view of the onion, if this action inspected it.
    p_blemished : float or None
        The classifier's fused probability that the onion is blemished, where it gave one.
    view_p_blemished : tuple of (float or None)
        Each view's, where it gave them.
    q : ndarray of shape (7,)
        The Sawyer's joint positions after the action.
    time_s : float
        The station's clock after the action, ``(step + 1) * STEP_DURATION_S``.
    onions : tuple of OnionLabel
        The onions in the world after the action, with their boxes in ``color`` when
        rendering (:meth:`robot.station.SawyerStation.onion_labels`).
    world : WorldState or None
        The world in 3D after the action (:meth:`robot.station.SawyerStation.world_state`).
    """

    step: int
    state: int
    action: int
    next_state: int
    onion: int | None
    blemished: bool | None
    perceived: Prediction | None
    fate: Fate | None
    tp: int
    fp: int
    tn: int
    fn: int
    color: np.ndarray | None = field(default=None, repr=False)
    depth: np.ndarray | None = field(default=None, repr=False)
    inspection: np.ndarray | None = field(default=None, repr=False)
    q: np.ndarray = field(default_factory=lambda: np.zeros(7), repr=False)
    time_s: float = 0.0
    onions: tuple[OnionLabel, ...] = field(default=(), repr=False)
    world: WorldState | None = field(default=None, repr=False)
    views: tuple[np.ndarray, ...] = field(default=(), repr=False)
    p_blemished: float | None = None
    view_p_blemished: tuple[float | None, ...] = field(default=(), repr=False)


@dataclass(frozen=True)
class StationView:
    """The station at rest at ``time_s``: before the first action (:func:`evaluate_policy`'s
    ``on_start``), or after an action (an :class:`EvaluationStep` has the same fields).

    Attributes
    ----------
    time_s : float
        The station's clock.
    color : ndarray of shape (H, W, 3) or None
        uint8 RGB of the main camera (when rendering).
    depth : ndarray of shape (H, W) or None
        float32 depth in metres (when rendering).
    onions : tuple of OnionLabel
        The onions in the world, with their boxes in ``color`` when rendering.
    world : WorldState
        The world in 3D.
    q : ndarray of shape (7,)
        The Sawyer's joint positions.
    """

    time_s: float
    color: np.ndarray | None = field(repr=False)
    depth: np.ndarray | None = field(repr=False)
    onions: tuple[OnionLabel, ...] = field(repr=False)
    world: WorldState = field(repr=False)
    q: np.ndarray = field(repr=False)


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


def _check_int(name: str, value, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
        raise ValueError(f"{name} must be an int >= {low}; got {value!r}")
    return int(value)


def evaluate_policy(
    actions: np.ndarray,
    *,
    n_onions: int = 50,
    n_blemished: int = 30,
    seed: int | np.random.SeedSequence = 0,
    classify: Classifier | Literal["ground-truth"],
    max_steps_per_onion: int = 12,
    render: bool = False,
    move_steps: int = 120,
    on_step: Callable[[EvaluationStep], None] | None = None,
    difficulty: Difficulty | str = "clean",
    on_start: Callable[[StationView], None] | None = None,
    inspection_views: int = INSPECTION_VIEWS,
    stop_when_settled: bool = True,
    confidence: np.ndarray | None = None,
    defer_below: float = 0.0,
) -> SortingResult:
    """Let the Sawyer sort a line-up of onions with the greedy policy ``actions``.

    Parameters
    ----------
    actions : ndarray of shape (48,) or (48, 5)
        Action index per state, or a policy ``pi[s, a]`` (its argmax per state is executed).
    n_onions, n_blemished : int
        Line-up size and how many of its onions are blemished (exactly).
    seed : int or numpy.random.SeedSequence
        Seeds the line-up and the scene; a run is reproducible from it (and a deterministic
        ``classify``).
    classify : callable or "ground-truth"
        ``classify(views) -> Prediction or Verdict`` on the onion's inspection views (each
        (h, w, 3) uint8; :data:`robot.classifier.Classifier`), or ``"ground-truth"`` for perfect
        perception.
    max_steps_per_onion : int
        The episode's step budget is ``n_onions * max_steps_per_onion`` actions.
    render : bool
        Render the main camera after every action (passed to ``on_step``), and before the first
        one for ``on_start``. The inspection view and the counts never depend on it.
    move_steps : int
        Physics steps per arm motion (see :class:`robot.station.SawyerStation`).
    on_step : callable, optional
        Called with an :class:`EvaluationStep` after every action.
    difficulty : Difficulty or str
        Perception difficulty of the station (:mod:`robot.difficulty`): the onions' blemishes
        and the inspection view the classifier reads; ``"clean"`` by default.
    on_start : callable, optional
        Called once with a :class:`StationView` of the station before the first action (its
        image drawn with noise of its own, so it changes no later render).
    inspection_views : int
        Views the robot takes of every onion it inspects (:func:`robot.station.inspection_poses`):
        the most it takes.
    stop_when_settled : bool
        Stop showing an onion once its call is settled (a sequential ``classify``; see
        :class:`robot.station.SawyerStation`): each onion's call from fewer views.
    confidence : ndarray of shape (48, 5) or (48,), optional
        How sure the policy is of each action in each state (the posterior share of reward
        samples whose greedy policy takes it, ``onionsort learn --posterior``), or of its own
        action in each state; :func:`confidence_in` reads it.
    defer_below : float
        With ``confidence``: where the robot's confidence in its next action
        (:func:`confidence_in`) is below this, the onion in focus is deferred to the check tray
        (:meth:`robot.station.SawyerStation.defer`) instead of acted on; 0 never defers.

    Returns
    -------
    SortingResult

    Raises
    ------
    ValueError
        If an argument is out of its domain (the message names it).
    """
    policy = greedy_actions(actions)
    n_onions = _check_int("n_onions", n_onions, 1)
    n_blemished = _check_int("n_blemished", n_blemished, 0)
    if n_blemished > n_onions:
        raise ValueError(f"n_blemished must be <= n_onions={n_onions}; got {n_blemished}")
    max_steps_per_onion = _check_int("max_steps_per_onion", max_steps_per_onion, 1)
    for name, callback in (("on_step", on_step), ("on_start", on_start)):
        if callback is not None and not callable(callback):
            raise TypeError(f"{name} must be callable or None; got {type(callback).__name__}")
    if confidence is not None:
        confidence = np.asarray(confidence, float)
        if confidence.shape not in ((N_STATES,), (N_STATES, N_ACTIONS)) \
                or not np.all((confidence >= 0) & (confidence <= 1)):
            raise ValueError(f"confidence must hold values in [0, 1], one per state "
                             f"({N_STATES}) or per state and action ({N_STATES}, {N_ACTIONS}); "
                             f"got shape {confidence.shape}")
    if not isinstance(defer_below, int | float) or not 0.0 <= defer_below <= 1.0:
        raise ValueError(f"defer_below must be in [0, 1]; got {defer_below!r}")
    budget = n_onions * max_steps_per_onion
    with SawyerStation(classify, n_onions=n_onions, n_blemished=n_blemished, seed=seed,
                       move_steps=move_steps, render_every_step=render,
                       difficulty=difficulty, inspection_views=inspection_views,
                       stop_when_settled=stop_when_settled) as station:
        tally = SortingTally(station.blemished)
        if on_start is not None:
            image = station.render(initial=True) if render else None
            on_start(StationView(
                time_s=0.0, color=None if image is None else image.rgb,
                depth=None if image is None else image.depth,
                onions=station.onion_labels(None if image is None else image.seg),
                world=station.world_state(), q=station.arm.q))
        n_steps = 0
        while n_steps < budget and not tally.complete:
            s = station.state
            a = SortAction(int(policy[encode_state(s)]))
            if (confidence is not None and station.focus is not None
                    and tally.fates[station.focus] is None
                    and confidence_in(confidence, s, a, tally.p_blemished.get(station.focus))
                    < defer_below):
                tally.defer(station.defer())  # not an action of the MDP: no step counted
                continue
            done = station.step(a)
            fate = tally.record(done)
            if on_step is not None:
                on_step(EvaluationStep(
                    step=n_steps, state=encode_state(done.state), action=int(a),
                    next_state=encode_state(done.next_state), onion=done.onion,
                    blemished=None if done.onion is None else tally.is_blemished(done.onion),
                    perceived=done.perceived, fate=fate, **tally.counts,
                    color=None if done.image is None else done.image.rgb,
                    depth=None if done.image is None else done.image.depth,
                    inspection=done.inspection, views=done.views,
                    p_blemished=done.p_blemished, view_p_blemished=done.view_p_blemished,
                    q=done.q,
                    time_s=(n_steps + 1) * STEP_DURATION_S,
                    onions=station.onion_labels(None if done.image is None else done.image.seg),
                    world=station.world_state(),
                ))
            n_steps += 1
        perceived = [station.perceived(i) for i in range(n_onions)]
    return tally.result(n_steps, perceived)


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


class SortingTally:
    """The fates of a line-up's onions and the running TP/FP/TN/FN, action by action.

    The one place where an episode is counted: :func:`evaluate_policy` and the Gymnasium
    environment (:mod:`robot.gym_env`) feed it every :class:`~robot.station.StationStep` and
    read the same counts.

    Parameters
    ----------
    blemished : ndarray of shape (n_onions,)
        The line-up's true classes (:attr:`robot.station.SawyerStation.blemished`).

    Attributes
    ----------
    fates : list of {"bin", "line"} or None
        Each onion's fate so far (None while undecided).
    counts : dict
        ``tp``, ``fp``, ``tn``, ``fn`` over the onions decided so far.
    """

    def __init__(self, blemished: np.ndarray) -> None:
        self._blemished = np.asarray(blemished, bool).copy()
        if self._blemished.ndim != 1 or not len(self._blemished):
            raise ValueError(f"blemished must be a non-empty 1-D array of classes; got shape "
                             f"{self._blemished.shape}")
        self.fates: list[Fate | None] = [None] * len(self._blemished)
        #: the inspection's latest probability that each inspected onion is blemished
        self.p_blemished: dict[int, float] = {}
        #: inspection views taken of each inspected onion
        self.views: dict[int, int] = {}
        self.counts = {"tp": 0, "fp": 0, "tn": 0, "fn": 0}

    def is_blemished(self, index: int) -> bool:
        """The true class of line-up onion ``index``."""
        return bool(self._blemished[index])

    @property
    def complete(self) -> bool:
        """Whether every onion has a fate (the episode is over)."""
        return all(f is not None for f in self.fates)

    def defer(self, index: int) -> None:
        """Onion ``index`` went to the check tray: decided, and counted apart."""
        self.fates[index] = "tray"

    def record(self, done: StationStep) -> Fate | None:
        """Count the fate ``done`` gave the onion in focus, and keep the probability its
        inspection gave; return the fate (None if it gave none)."""
        if done.p_blemished is not None:
            self.p_blemished[done.onion] = done.p_blemished
        if done.views:
            self.views[done.onion] = self.views.get(done.onion, 0) + len(done.views)
        fate = _fate(done.action, done.next_state) if done.changed else None
        if fate is not None:
            self.fates[done.onion] = fate
            self.counts[_cell(self.is_blemished(done.onion), fate)] += 1
        return fate

    def result(self, n_steps: int, perceived: list[Prediction | None]) -> SortingResult:
        """The episode's :class:`SortingResult` after ``n_steps`` actions; onions still
        undecided count as left on the line. ``perceived`` (n_onions,) is what the robot
        perceived of each onion (None if never inspected)."""
        p_blemished = self.p_blemished
        n_onions = len(self.fates)
        if len(perceived) != n_onions:
            raise ValueError(f"perceived must hold one entry per onion ({n_onions}); got "
                             f"{len(perceived)}")
        undecided = sum(f is None for f in self.fates)
        if undecided:
            logger.info("the episode ended after %d steps with %d of %d onions undecided (left "
                        "on the line)", n_steps, undecided, n_onions)
        outcomes = tuple(
            OnionOutcome(index=i, blemished=self.is_blemished(i), perceived=perceived[i],
                         fate=self.fates[i] or "line", decided=self.fates[i] is not None,
                         p_blemished=p_blemished.get(i), views=self.views.get(i, 0))
            for i in range(n_onions)
        )
        final = {"tp": 0, "fp": 0, "tn": 0, "fn": 0}
        for o in outcomes:
            if o.fate != "tray":
                final[_cell(o.blemished, o.fate)] += 1
        result = SortingResult(**final, n_steps=n_steps, undecided=undecided, onions=outcomes,
                               deferred=sum(o.fate == "tray" for o in outcomes))
        logger.info("sorted %d onions in %d steps: precision %.3f, recall %.3f", n_onions,
                    n_steps, result.precision, result.recall)
        return result


def _fate(action: SortAction, next_state) -> Fate | None:
    """The fate an action that changed the state gave the onion in focus, if final."""
    if action == SortAction.PLACE_IN_BIN:
        return "bin"
    if action == SortAction.PLACE_ON_CONVEYOR and next_state.prediction != Prediction.UNKNOWN:
        return "line"
    return None


def _cell(blemished: bool, fate: Fate) -> str:
    if fate == "bin":
        return "tp" if blemished else "fp"
    return "fn" if blemished else "tn"
