"""The sorting evaluation: the Sawyer executes a greedy policy on a line-up of onions.

Policies are ``actions[s]`` (48,) — an action index per state index of
:mod:`irl.domains.onion_sorting` — or ``pi[s, a]`` (48, 5), whose argmax is taken.

:func:`evaluate_policy` builds the Sawyer's station (:class:`robot.station.SawyerStation`) for
a seeded line-up and runs the sorting loop on it (:class:`robot.cell.SortingRun`, the loop
every cell goes through). The episode starts in :data:`robot.cell.START_STATE` (the MDP's
initial state, nothing claimed yet) and ends when every onion has a fate or the step budget
``n_onions * max_steps_per_onion`` is spent; onions still undecided then (never claimed, or
claimed and not yet released for good) count as left on the line. With a confidence and
``defer_below``, the robot defers where it is less sure than the threshold that its next action
is right (:func:`confidence_in`): the onion in focus goes to a check tray for a person (fate
``"tray"``) and is counted apart, in ``deferred``. The counts, precision and recall and their
intervals are :mod:`robot.tally`'s.

For logging and recording, :func:`evaluate_policy` reports the station at rest before the first
action (``on_start``, a :class:`StationView`) and after every action (``on_step``, an
:class:`EvaluationStep`: the decision, the running counts and the same view): the camera's
images when rendering, the onions in the world, a snapshot of the world in 3D
(:class:`robot.world.WorldState`) and the joints.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from irl.domains.onion_sorting import Prediction, encode_state
from robot.cell import SortingRun, check_confidence, confidence_in, greedy_actions
from robot.classifier import Classifier
from robot.difficulty import Difficulty
from robot.labels import OnionLabel
from robot.station import INSPECTION_VIEWS, STEP_DURATION_S, SawyerStation
from robot.tally import Fate, OnionOutcome, SortingResult, SortingTally, _PrecisionRecall
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
    confidence = check_confidence(confidence)
    if isinstance(defer_below, bool) or not isinstance(defer_below, int | float) \
            or not 0.0 <= defer_below <= 1.0:
        raise ValueError(f"defer_below must be in [0, 1]; got {defer_below!r}")
    with SawyerStation(classify, n_onions=n_onions, n_blemished=n_blemished, seed=seed,
                       move_steps=move_steps, render_every_step=False,
                       difficulty=difficulty, inspection_views=inspection_views,
                       stop_when_settled=stop_when_settled) as station:
        run = SortingRun(station, n_onions, station.reader, truth=station.blemished,
                         max_steps_per_onion=max_steps_per_onion, confidence=confidence,
                         defer_below=defer_below)
        if on_start is not None:
            image = station.render(initial=True) if render else None
            on_start(StationView(
                time_s=0.0, color=None if image is None else image.rgb,
                depth=None if image is None else image.depth,
                onions=station.onion_labels(None if image is None else image.seg),
                world=station.world_state(), q=station.arm.q))

        def report(done, fate: Fate | None) -> None:
            image = station.render() if render else None
            tally = run.tally
            on_step(EvaluationStep(
                step=run.n_steps - 1, state=encode_state(done.state), action=int(done.action),
                next_state=encode_state(done.next_state), onion=done.onion,
                blemished=None if done.onion is None else tally.is_blemished(done.onion),
                perceived=done.perceived, fate=fate, **tally.counts,
                color=None if image is None else image.rgb,
                depth=None if image is None else image.depth,
                inspection=done.views[0] if done.views else None, views=done.views,
                p_blemished=done.p_blemished, view_p_blemished=done.view_p_blemished,
                q=station.arm.q, time_s=run.n_steps * STEP_DURATION_S,
                onions=station.onion_labels(None if image is None else image.seg),
                world=station.world_state(),
            ))

        run.run(policy, report if on_step is not None else None)
    return run.result()
