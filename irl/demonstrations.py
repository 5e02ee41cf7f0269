"""Demonstrations as observation sequences with explicit occluded steps.

A :class:`Demonstration` is what the learners see: one observation index per time step, or
``None`` where the step was occluded. A :class:`Trajectory` is the ground truth ``(s_t, a_t)``
behind it, used only to generate data and to score, never by the learners; a
:class:`StepTruth` is one step of it as a simulator produces it and a recording stores it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from irl._random import check_random_state
from irl._validation import check_int, check_real, describe

__all__ = [
    "OCCLUDED",
    "Demonstration",
    "StepTruth",
    "Trajectory",
    "check_demonstrations",
    "observe",
    "pack_observations",
    "sample_trajectory",
]

OCCLUDED = -1
"""Array code of an occluded step in packed observation arrays."""


@dataclass(frozen=True)
class Demonstration:
    """One demonstration: ``observations[t]`` is an observation index, or ``None`` if occluded.

    What an index means is the observation model's: for a pair model ``o = s' * A + a'`` (the
    state and action read), for a state model ``o = s'``. Build one from logged pairs with
    :meth:`from_pairs` (for the identity model) or by computing the indices.

    Parameters
    ----------
    observations : sequence of int or None
        One entry per step, at least one: an index ``>= 0`` (numpy integers accepted), or
        ``None`` for an occluded step.

    Attributes
    ----------
    observations : tuple of int or None
        As given, numpy integers made ``int``.

    Examples
    --------
    >>> Demonstration(observations=[3, None, 7]).n_occluded
    1
    """

    observations: tuple[int | None, ...]

    def __post_init__(self) -> None:
        raw = self.observations
        if isinstance(raw, (str, bytes, dict, set)) or not hasattr(raw, "__iter__"):
            raise TypeError(
                f"observations must be a sequence of int or None; got {describe(raw)}"
            )
        obs = tuple(raw)
        clean: list[int | None] = []
        for t, o in enumerate(obs):
            if o is None:
                clean.append(None)
            elif isinstance(o, (bool, np.bool_)) or not isinstance(o, (int, np.integer)):
                raise TypeError(
                    f"observations[{t}] must be an int or None; got {type(o).__name__} {o!r}"
                )
            elif o < 0:
                raise ValueError(f"observations[{t}] must be >= 0 or None; got {o}")
            else:
                clean.append(int(o))
        if not clean:
            raise ValueError("observations must hold at least one step; got an empty sequence")
        object.__setattr__(self, "observations", tuple(clean))

    def __len__(self) -> int:
        return len(self.observations)

    @property
    def occluded(self) -> np.ndarray:
        """Boolean mask of occluded steps, shape (T,)."""
        return np.array([o is None for o in self.observations])

    @property
    def n_occluded(self) -> int:
        return int(self.occluded.sum())

    def as_array(self) -> np.ndarray:
        """Observation indices, shape (T,), with :data:`OCCLUDED` (-1) at occluded steps."""
        return np.array([OCCLUDED if o is None else o for o in self.observations], dtype=np.int64)

    @classmethod
    def from_pairs(
        cls, states: Sequence[int], actions: Sequence[int], n_actions: int,
        occluded: Sequence[bool] | None = None,
    ) -> Demonstration:
        """A fully observed demonstration of ``(s_t, a_t)`` pairs, for the identity model.

        The observation index is ``s * n_actions + a``, as in
        :func:`irl.observation.identity_observation_model`.
        """
        n_actions = check_int(n_actions, "n_actions", low=1)
        states, actions = _indices(states, "states"), _indices(actions, "actions")
        if states.shape != actions.shape:
            raise ValueError(
                f"states and actions must be 1-D of equal length; got {states.shape} and "
                f"{actions.shape}"
            )
        if actions.size and actions.max() >= n_actions:
            raise ValueError(f"actions must lie in [0, {n_actions}); got {actions.max()}")
        if occluded is None:
            mask = np.zeros(len(states), bool)
        else:
            mask = np.asarray(occluded)
            if mask.shape != states.shape:
                raise ValueError(
                    f"occluded must have the shape of states {states.shape}; got {mask.shape}"
                )
            if mask.dtype != bool and not (
                np.issubdtype(mask.dtype, np.number) and np.isin(mask, (0, 1)).all()
            ):
                raise TypeError(f"occluded must hold booleans; got dtype {mask.dtype}")
            mask = mask.astype(bool)
        obs = states * n_actions + actions
        return cls(observations=[None if m else int(o) for o, m in zip(obs, mask, strict=True)])


@dataclass(frozen=True)
class Trajectory:
    """Ground-truth states and actions of one demonstration.

    Parameters
    ----------
    states, actions : array of int, shape (T,)
        ``s_t`` and ``a_t``, non-negative, of equal length.

    Attributes
    ----------
    states, actions : ndarray of int64, shape (T,)
    """

    states: np.ndarray = field(repr=False)
    actions: np.ndarray = field(repr=False)

    def __post_init__(self) -> None:
        s, a = _indices(self.states, "states"), _indices(self.actions, "actions")
        if s.shape != a.shape or s.ndim != 1:
            raise ValueError(
                f"states and actions must be 1-D of equal length; got {s.shape} and {a.shape}"
            )
        object.__setattr__(self, "states", s)
        object.__setattr__(self, "actions", a)

    def __len__(self) -> int:
        return len(self.states)


@dataclass(frozen=True)
class StepTruth:
    """One step's ground truth: at step ``step`` the demonstrator in ``state`` took ``action``
    and reached ``next_state``; ``occluded`` says whether the observer's view was blocked.

    States and actions are flat indices of the task (:mod:`irl.domains`). A simulator
    produces these and a session stores and reads them back; a sequence of them is a
    :class:`Trajectory` with its occlusion mask.

    Attributes
    ----------
    step : int
        The step's index in its session.
    state, action, next_state : int
        ``s_t``, ``a_t`` and ``s_{t+1}``.
    occluded : bool
        Whether the observer's view of the step was blocked.
    """

    step: int
    state: int
    action: int
    next_state: int
    occluded: bool


def _indices(values, name: str) -> np.ndarray:
    """A 1-D array of non-negative integers, or raise naming ``name``."""
    if values is None or isinstance(values, (str, bytes, dict, set)):
        raise TypeError(f"{name} must be a 1-D array of integers; got {describe(values)}")
    try:
        arr = np.asarray(values)
    except ValueError as exc:  # ragged
        raise ValueError(f"{name} must be a 1-D array of integers; got {exc}") from None
    if arr.size and (arr.dtype == bool or not np.issubdtype(arr.dtype, np.integer)):
        raise TypeError(f"{name} must be a 1-D array of integers; got dtype {arr.dtype}")
    if arr.ndim != 1:
        raise ValueError(f"{name} must be 1-D; got shape {arr.shape}")
    if arr.size and arr.min() < 0:
        raise ValueError(f"{name} must be >= 0; got {arr.min()}")
    return arr.astype(np.int64)


def check_demonstrations(demos, n_observations: int) -> list[Demonstration]:
    """Validate a collection of demonstrations against an observation space.

    Raises ``TypeError``/``ValueError`` naming the demonstration (``demos[i]``) and the step at
    fault.

    Parameters
    ----------
    demos : sequence of Demonstration
        At least one.
    n_observations : int
        Every observation index must be below it.

    Returns
    -------
    list of Demonstration
        ``demos`` as a list.
    """
    if isinstance(demos, Demonstration):
        raise TypeError("demos must be a sequence of Demonstration; got a single Demonstration")
    if demos is None or isinstance(demos, (str, bytes, dict)) or not hasattr(demos, "__iter__"):
        raise TypeError(f"demos must be a sequence of Demonstration; got {describe(demos)}")
    demos = list(demos)
    if not demos:
        raise ValueError("demos must hold at least one Demonstration; got none")
    for i, d in enumerate(demos):
        if not isinstance(d, Demonstration):
            raise TypeError(f"demos[{i}] must be a Demonstration; got {type(d).__name__}")
        obs = d.as_array()
        bad = np.flatnonzero(obs >= n_observations)
        if bad.size:
            t = int(bad[0])
            raise ValueError(
                f"demos[{i}], step {t}: observation {obs[t]} is out of range for an "
                f"observation model with {n_observations} observations"
            )
    return demos


def pack_observations(demos: Sequence[Demonstration], n_observations: int) -> np.ndarray:
    """Stack demonstrations of one length into an array (N, T) with -1 for occluded steps.

    Raises ``ValueError`` naming the demonstration and step of an out-of-range observation.

    Parameters
    ----------
    demos : sequence of Demonstration
        All of one length ``T``.
    n_observations : int

    Returns
    -------
    ndarray of int64, shape (N, T)
        Observation indices, :data:`OCCLUDED` (-1) at occluded steps.
    """
    lengths = {len(d) for d in demos}
    if len(lengths) != 1:
        raise ValueError(f"demonstrations packed together must share a length; got {lengths}")
    packed = np.stack([d.as_array() for d in demos])
    bad = np.argwhere(packed >= n_observations)
    if bad.size:
        i, t = bad[0]
        raise ValueError(
            f"demos[{i}], step {t}: observation {packed[i, t]} is out of range for an "
            f"observation model with {n_observations} observations"
        )
    return packed


def sample_trajectory(
    mdp, policy: np.ndarray, length: int, seed=None, *, initial_state: int | None = None
) -> Trajectory:
    """Roll out a stochastic policy ``pi[s, a]`` for ``length`` steps.

    The first state is drawn from ``mdp.initial`` unless ``initial_state`` is given.

    Parameters
    ----------
    mdp : TabularMDP
    policy : ndarray of shape (S, A)
        ``pi[s, a]``, each row a distribution over actions.
    length : int
        Steps, >= 1.
    seed : int, Generator or None
    initial_state : int, optional
        The first state instead of a draw (keyword only).

    Returns
    -------
    Trajectory
        The states visited and the actions taken.
    """
    rng = check_random_state(seed)
    length = check_int(length, "length", low=1)
    policy = np.asarray(policy, dtype=float)
    if policy.shape != (mdp.n_states, mdp.n_actions):
        raise ValueError(
            f"policy must have shape (S, A) = ({mdp.n_states}, {mdp.n_actions}); got "
            f"{policy.shape}"
        )
    if initial_state is not None:
        initial_state = check_int(initial_state, "initial_state", low=0, high=mdp.n_states - 1)
    states = np.empty(length, dtype=np.int64)
    actions = np.empty(length, dtype=np.int64)
    s = rng.choice(mdp.n_states, p=mdp.initial) if initial_state is None else int(initial_state)
    for t in range(length):
        a = rng.choice(mdp.n_actions, p=policy[s])
        states[t], actions[t] = s, a
        if t + 1 < length:
            s = rng.choice(mdp.n_states, p=mdp.next_state_distribution(s, a))
    return Trajectory(states=states, actions=actions)


def observe(
    trajectory: Trajectory, observation_model, occlusion: float, seed=None
) -> Demonstration:
    """Observe a ground-truth trajectory through ``O`` with ``round(occlusion * T)`` steps occluded.

    The occluded steps are drawn uniformly without replacement; the others emit
    ``o ~ O[s_t, a_t, :]``.

    Parameters
    ----------
    trajectory : Trajectory
    observation_model : ObservationModel
    occlusion : float in [0, 1]
        The share of steps occluded.
    seed : int, Generator or None

    Returns
    -------
    Demonstration
        What an observer of the trajectory sees.
    """
    rng = check_random_state(seed)
    occlusion = check_real(occlusion, "occlusion", low=0.0, high=1.0)
    if not isinstance(trajectory, Trajectory):
        raise TypeError(f"trajectory must be an irl.Trajectory; got {type(trajectory).__name__}")
    T = len(trajectory)
    n_hidden = round(occlusion * T)
    hidden = np.zeros(T, bool)
    hidden[rng.choice(T, size=n_hidden, replace=False)] = True
    obs: list[int | None] = []
    for t in range(T):
        if hidden[t]:
            obs.append(None)
        else:
            p = observation_model.distribution(trajectory.states[t], trajectory.actions[t])
            obs.append(int(rng.choice(len(p), p=p)))
    return Demonstration(observations=obs)
