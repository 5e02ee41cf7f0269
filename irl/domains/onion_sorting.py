"""The onion-sorting MDP: the one definition of its states, actions and features.

The simulator (``robot/``), the perception pipeline (``state_abstraction/``), the recordings and
the robot all take the encoding from here; nobody re-declares it. :data:`SORTING_TASK` is the
same task as data (a :class:`~irl.domains.task.TaskDescription` built from the enums below), for
code that should not depend on the enums.

State factors (the paper's text; 4 x 4 x 3 = 48 states, see docs/paper-errata.md on "144"):

- ``onion``: where the onion in focus is — :class:`Location` CONVEYOR, HOVER, FACE, BIN;
- ``end_effector``: where the sorter's hand is — the same four locations;
- ``prediction``: what the sorter knows of the onion — :class:`Prediction` GOOD, BAD, UNKNOWN.

``state = (onion * 4 + end_effector) * 3 + prediction`` (row-major, ``np.ravel_multi_index``).

Actions (:class:`SortAction`): CLAIM a new onion, PICK, INSPECT after picking, PLACE_ON_CONVEYOR,
PLACE_IN_BIN. The transition rules, in the order they are checked:

=================  ==============================================  ==========================
action             applies when                                    next state
=================  ==============================================  ==========================
CLAIM              no onion in focus: onion in BIN, or on          (CONVEYOR, hand, UNKNOWN)
                   CONVEYOR with a known prediction (placed back)
PICK               the onion in focus (on CONVEYOR, UNKNOWN)       (HOVER, HOVER, UNKNOWN)
INSPECT            onion held (at HOVER or FACE)                   (FACE, FACE, pred'), pred'
                                                                   BAD w.p. the blemish rate,
                                                                   else GOOD, if pred UNKNOWN
PLACE_ON_CONVEYOR  onion held                                      (CONVEYOR, CONVEYOR, pred)
PLACE_IN_BIN       onion held                                      (BIN, BIN, pred)
any other (s, a)                                                   s (nothing happens)
=================  ==============================================  ==========================

Features (Boolean, on ``(s, a)``): good onion placed on conveyor, bad onion placed on conveyor,
good onion placed in bin, bad onion placed in bin, claim new onion (when no onion is in focus),
pick if unknown. Under the true weights the expert's greedy policy is
claim -> pick -> inspect -> bad to bin / good to conveyor -> claim.
"""

from __future__ import annotations

from enum import IntEnum
from typing import NamedTuple, get_type_hints

import numpy as np

from irl._validation import check_real
from irl.domains.base import Domain
from irl.domains.task import TaskDescription
from irl.mdp import TabularMDP
from irl.observation import ObservationModel, factored_observation_model
from irl.priors import GaussianPrior

__all__ = [
    "FACTOR_SIZES",
    "N_ACTIONS",
    "N_STATES",
    "SORTING_TASK",
    "FeatureName",
    "Location",
    "Prediction",
    "SortAction",
    "SortingState",
    "decode_state",
    "describe_state",
    "encode_state",
    "misplacement_costs",
    "next_state",
    "onion_sorting",
    "sorting_features",
    "sorting_transitions",
    "transition_table_markdown",
]


class Location(IntEnum):
    """Where the onion or the end effector is.

    Attributes
    ----------
    CONVEYOR, HOVER, FACE, BIN : int
        On the conveyor, just above it, at the inspection pose, in (or over) the bin.
    """

    CONVEYOR = 0
    HOVER = 1
    FACE = 2
    BIN = 3


class Prediction(IntEnum):
    """The sorter's belief about the onion in focus.

    Attributes
    ----------
    GOOD, BAD, UNKNOWN : int
        Inspected and sound, inspected and blemished, not inspected yet.
    """

    GOOD = 0
    BAD = 1
    UNKNOWN = 2


class SortAction(IntEnum):
    """The sorter's abstract actions.

    Attributes
    ----------
    CLAIM, PICK, INSPECT, PLACE_ON_CONVEYOR, PLACE_IN_BIN : int
        Take the next onion in focus, lift it, look at it at the inspection pose, put it back
        on the line, drop it in the bin.
    """

    CLAIM = 0
    PICK = 1
    INSPECT = 2
    PLACE_ON_CONVEYOR = 3
    PLACE_IN_BIN = 4


class FeatureName(IntEnum):
    """Indices of the reward features.

    Attributes
    ----------
    GOOD_ON_CONVEYOR, BAD_ON_CONVEYOR, GOOD_IN_BIN, BAD_IN_BIN : int
        Placing an inspected onion of that class there.
    CLAIM_NEW_ONION, PICK_IF_UNKNOWN : int
        Claiming an onion when none is in focus; picking up the onion in focus.
    """

    GOOD_ON_CONVEYOR = 0
    BAD_ON_CONVEYOR = 1
    GOOD_IN_BIN = 2
    BAD_IN_BIN = 3
    CLAIM_NEW_ONION = 4
    PICK_IF_UNKNOWN = 5


class SortingState(NamedTuple):
    """A factored onion-sorting state.

    Attributes
    ----------
    onion, end_effector : Location
        Where the onion in focus and the gripper are.
    prediction : Prediction
        The sorter's belief about the onion in focus.
    """

    onion: Location
    end_effector: Location
    prediction: Prediction


# The constructor namedtuple generates lives in no module, so its annotations (strings here)
# cannot be resolved from it: resolve them once, for whatever reads its signature.
SortingState.__new__.__annotations__ = get_type_hints(SortingState)

_FACTOR_ENUMS = (Location, Location, Prediction)

#: The sorting task as data: factors ``onion``, ``end_effector``, ``prediction`` (in the order of
#: :class:`SortingState`, the first most significant) with the lowercased enum names as values,
#: and the lowercased :class:`SortAction` and :class:`FeatureName` names.
SORTING_TASK = TaskDescription(
    name="onion-sorting",
    factors={
        field: tuple(v.name.lower() for v in enum)
        for field, enum in zip(SortingState._fields, _FACTOR_ENUMS, strict=True)
    },
    action_names=tuple(a.name.lower() for a in SortAction),
    feature_names=tuple(f.name.lower() for f in FeatureName),
)

FACTOR_SIZES = SORTING_TASK.factor_sizes
N_STATES = SORTING_TASK.n_states
N_ACTIONS = SORTING_TASK.n_actions


def encode_state(state: SortingState | tuple[int, int, int]) -> int:
    """Flat state index of ``(onion, end_effector, prediction)``.

    Parameters
    ----------
    state : SortingState or tuple of three int

    Returns
    -------
    int
        ``s`` in ``[0, 48)``, as :data:`SORTING_TASK` encodes it.
    """
    return SORTING_TASK.encode(tuple(int(x) for x in state))


def decode_state(index: int) -> SortingState:
    """The factored state of a flat index.

    Parameters
    ----------
    index : int
        ``s`` in ``[0, 48)``.

    Returns
    -------
    SortingState
    """
    values = SORTING_TASK.decode(int(index)).values()
    return SortingState(*(enum(v) for enum, v in zip(_FACTOR_ENUMS, values, strict=True)))


_ONION_WORDS = {Prediction.GOOD: "a good onion", Prediction.BAD: "a blemished onion",
                Prediction.UNKNOWN: "an uninspected onion"}
_PLACE_WORDS = {Location.CONVEYOR: "on the conveyor", Location.HOVER: "above the conveyor",
                Location.FACE: "at the inspection pose", Location.BIN: "in the bin"}
_GRIPPER_WORDS = {**_PLACE_WORDS, Location.CONVEYOR: "at the conveyor",
                  Location.BIN: "over the bin"}


def describe_state(index: int) -> str:
    """State ``index`` in the task's words, e.g. "a blemished onion held at the inspection
    pose".

    Parameters
    ----------
    index : int

    Returns
    -------
    str
    """
    s = decode_state(index)
    onion = _ONION_WORDS[s.prediction]
    if _holding(s) and s.end_effector == s.onion:
        return f"{onion} held {_PLACE_WORDS[s.onion]}"
    return f"{onion} {_PLACE_WORDS[s.onion]}, the gripper {_GRIPPER_WORDS[s.end_effector]}"


def _holding(s: SortingState) -> bool:
    return s.onion in (Location.HOVER, Location.FACE)


def _no_onion_in_focus(s: SortingState) -> bool:
    return s.onion == Location.BIN or (
        s.onion == Location.CONVEYOR and s.prediction != Prediction.UNKNOWN
    )


def _onion_in_focus_on_conveyor(s: SortingState) -> bool:
    return s.onion == Location.CONVEYOR and s.prediction == Prediction.UNKNOWN


def next_state(state: SortingState, action: SortAction, blemished: bool) -> SortingState:
    """The next state when the onion in focus is (or, once claimed, will prove) ``blemished``.

    This is the deterministic core of the transition model: the only randomness in the MDP is
    the class of the onion, revealed by INSPECT. The simulator calls this with the physical
    onion's class.

    Parameters
    ----------
    state : SortingState
    action : SortAction
    blemished : bool
        The class the onion in focus has (or will prove to have at INSPECT).

    Returns
    -------
    SortingState
        ``state`` itself where the action does not apply.
    """
    s = SortingState(Location(state[0]), Location(state[1]), Prediction(state[2]))
    action = SortAction(action)
    if action == SortAction.CLAIM and _no_onion_in_focus(s):
        return SortingState(Location.CONVEYOR, s.end_effector, Prediction.UNKNOWN)
    if action == SortAction.PICK and _onion_in_focus_on_conveyor(s):
        return SortingState(Location.HOVER, Location.HOVER, s.prediction)
    if action == SortAction.INSPECT and _holding(s):
        pred = s.prediction
        if pred == Prediction.UNKNOWN:
            pred = Prediction.BAD if blemished else Prediction.GOOD
        return SortingState(Location.FACE, Location.FACE, pred)
    if action == SortAction.PLACE_ON_CONVEYOR and _holding(s):
        return SortingState(Location.CONVEYOR, Location.CONVEYOR, s.prediction)
    if action == SortAction.PLACE_IN_BIN and _holding(s):
        return SortingState(Location.BIN, Location.BIN, s.prediction)
    return s


def sorting_transitions(blemish_rate: float = 0.5) -> np.ndarray:
    """``T[s, a, s']`` of the sorting MDP; INSPECT reveals BAD with probability ``blemish_rate``.

    Parameters
    ----------
    blemish_rate : float in [0, 1]

    Returns
    -------
    ndarray of shape (48, 5, 48)
    """
    if not 0.0 <= blemish_rate <= 1.0:
        raise ValueError(f"blemish_rate must be in [0, 1]; got {blemish_rate}")
    T = np.zeros((N_STATES, N_ACTIONS, N_STATES))
    for s in range(N_STATES):
        state = decode_state(s)
        for a in SortAction:
            T[s, a, encode_state(next_state(state, a, blemished=True))] += blemish_rate
            T[s, a, encode_state(next_state(state, a, blemished=False))] += 1.0 - blemish_rate
    return T


def sorting_features() -> np.ndarray:
    """``phi[s, a, k]``: the six Boolean features of :class:`FeatureName`.

    Returns
    -------
    ndarray of shape (48, 5, 6)
    """
    phi = np.zeros((N_STATES, N_ACTIONS, len(FeatureName)))
    for s in range(N_STATES):
        st = decode_state(s)
        if _holding(st):
            for action, good_k, bad_k in (
                (SortAction.PLACE_ON_CONVEYOR, FeatureName.GOOD_ON_CONVEYOR,
                 FeatureName.BAD_ON_CONVEYOR),
                (SortAction.PLACE_IN_BIN, FeatureName.GOOD_IN_BIN, FeatureName.BAD_IN_BIN),
            ):
                if st.prediction == Prediction.GOOD:
                    phi[s, action, good_k] = 1.0
                elif st.prediction == Prediction.BAD:
                    phi[s, action, bad_k] = 1.0
        if _no_onion_in_focus(st):
            phi[s, SortAction.CLAIM, FeatureName.CLAIM_NEW_ONION] = 1.0
        if _onion_in_focus_on_conveyor(st):
            phi[s, SortAction.PICK, FeatureName.PICK_IF_UNKNOWN] = 1.0
    return phi


def state_name(index: int) -> str:
    """``"(onion, end_effector, prediction)"`` in lowercase, e.g. ``"(conveyor, hover, good)"``."""
    return SORTING_TASK.state_name(int(index))


def reachable_states() -> list[int]:
    """States reachable from the initial states, in breadth-first order."""
    start = [
        encode_state((Location.CONVEYOR, Location.CONVEYOR, Prediction.GOOD)),
        encode_state((Location.BIN, Location.BIN, Prediction.BAD)),
    ]
    seen, frontier = list(start), list(start)
    while frontier:
        s = decode_state(frontier.pop(0))
        for a in SortAction:
            for blemished in (True, False):
                n = encode_state(next_state(s, a, blemished))
                if n not in seen:
                    seen.append(n)
                    frontier.append(n)
    return seen


def transition_table_markdown() -> str:
    """The transitions and features of every reachable state, as a Markdown table.

    Returns
    -------
    str
        The table of docs/onion-sorting.md.
    """
    names = [f.name.lower() for f in FeatureName]
    phi = sorting_features()
    rows = ["| state (onion, hand, prediction) | action | next state | features |",
            "|---|---|---|---|"]
    for s in reachable_states():
        st = decode_state(s)
        for a in SortAction:
            bad, good = next_state(st, a, True), next_state(st, a, False)
            nxt = state_name(encode_state(bad)) if bad == good else (
                f"{state_name(encode_state(bad))} if blemished, else "
                f"{state_name(encode_state(good))}")
            if bad == good == st:
                nxt = "unchanged"
            feats = ", ".join(names[k] for k in np.flatnonzero(phi[s, a])) or ""
            rows.append(f"| {s} {state_name(s)} | {a.name.lower()} | {nxt} | {feats} |")
    return "\n".join(rows)


#: The expert's weights: keep good onions on the line, bin blemished ones, keep claiming and
#: picking. Their direction fixes the greedy policy; with beta = 1.5 the Boltzmann sorter takes
#: its greedy action about 85% of the time (only beta * theta is identifiable).
TRUE_THETA = np.array([4.0, -4.0, -4.0, 4.0, 2.0, 2.0])


def misplacement_costs(theta: np.ndarray | None = None) -> tuple[float, float]:
    """What misplacing an onion costs under the reward weights ``theta`` (6,) (the expert's,
    :data:`TRUE_THETA`, by default): ``(miss, waste)``, the reward lost by leaving a blemished
    onion on the line instead of binning it, ``theta[bad_in_bin] - theta[bad_on_conveyor]``,
    and by binning a good one instead of keeping it, ``theta[good_on_conveyor] -
    theta[good_in_bin]``. Either placement ends the onion's turn the same way (the next step
    claims another), so these are the differences of the two actions' values too.

    Parameters
    ----------
    theta : ndarray of shape (6,), optional
        Reward weights; :data:`TRUE_THETA` by default.

    Returns
    -------
    miss, waste : float
        The two costs, each >= 0.

    Raises
    ------
    ValueError
        If ``theta`` does not have one weight per feature, or a cost is negative (such a reward
        prefers the misplacement).
    """
    th = TRUE_THETA if theta is None else np.asarray(theta, float)
    if th.shape != (len(FeatureName),) or not np.all(np.isfinite(th)):
        raise ValueError(f"theta must hold {len(FeatureName)} finite weights; got shape "
                         f"{np.shape(th)}")
    miss = float(th[FeatureName.BAD_IN_BIN] - th[FeatureName.BAD_ON_CONVEYOR])
    waste = float(th[FeatureName.GOOD_ON_CONVEYOR] - th[FeatureName.GOOD_IN_BIN])
    if miss < 0 or waste < 0:
        raise ValueError(f"theta prefers misplacing onions (miss cost {miss}, waste cost "
                         f"{waste}); the costs must be >= 0")
    return miss, waste


def factor_confusion(n: int, error: float) -> np.ndarray:
    """A confusion matrix that misreads a value w.p. ``error``, uniformly over the others."""
    if n == 1:
        return np.ones((1, 1))
    return np.full((n, n), error / (n - 1)) + np.eye(n) * (1.0 - error - error / (n - 1))


def sorting_observation_model(noise: float) -> ObservationModel:
    """Observations of the pair with every state factor misread independently.

    Each of the three factors is misread with probability ``1 - (1 - noise)^(1/3)``, so the
    observed state is wrong with probability ``noise``; actions are observed exactly.
    """
    noise = check_real(noise, "noise", low=0.0, high=1.0, high_open=True)
    per_factor = 1.0 - (1.0 - noise) ** (1.0 / len(FACTOR_SIZES))
    return factored_observation_model(
        [factor_confusion(n, per_factor) for n in FACTOR_SIZES], n_actions=N_ACTIONS
    )


def onion_sorting(
    *, noise: float = 0.3, blemish_rate: float = 0.5, discount: float = 0.99, beta: float = 1.5
) -> Domain:
    """The onion-sorting domain of the paper (48 states, 5 actions, 6 features).

    Parameters
    ----------
    noise : float
        Probability that the observed state is wrong (the paper estimated about 0.3).
    blemish_rate : float
        Probability that a newly claimed onion is blemished.
    discount, beta : float
        The paper's gamma = 0.99, and the sorter's Boltzmann rationality.

    Returns
    -------
    Domain
        With the true weights :data:`TRUE_THETA`, the prior ``N(0, 3^2)`` per weight and the
        task :data:`SORTING_TASK`.
    """
    noise = check_real(noise, "noise", low=0.0, high=1.0, high_open=True)
    blemish_rate = check_real(blemish_rate, "blemish_rate", low=0.0, high=1.0)
    beta = check_real(beta, "beta", low=0.0, low_open=True)
    initial = np.zeros(N_STATES)
    for s in (
        SortingState(Location.CONVEYOR, Location.CONVEYOR, Prediction.GOOD),
        SortingState(Location.BIN, Location.BIN, Prediction.BAD),
    ):
        initial[encode_state(s)] = 0.5
    mdp = TabularMDP(
        transitions=sorting_transitions(blemish_rate),
        features=sorting_features(),
        discount=discount,
        initial=initial,
        state_names=list(SORTING_TASK.state_names),
        action_names=list(SORTING_TASK.action_names),
        feature_names=list(SORTING_TASK.feature_names),
    )
    return Domain(
        name="onion-sorting",
        mdp=mdp,
        true_theta=TRUE_THETA.copy(),
        observation_model=sorting_observation_model(noise),
        beta=beta,
        prior=GaussianPrior(mean=0.0, std=3.0),
        task=SORTING_TASK,
    )
