"""Demonstrations as observation sequences with explicit occluded steps.

A :class:`Demonstration` is what the learners see: one observation index per time step, or
``None`` where the step was occluded. A :class:`Trajectory` is the ground truth ``(s_t, a_t)``
behind it, used only to generate data and to score, never by the learners.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from irl._random import check_random_state

__all__ = [
    "OCCLUDED",
    "Demonstration",
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

    Examples
    --------
    >>> Demonstration(observations=[3, None, 7]).n_occluded
    1
    """

    observations: tuple[int | None, ...]

    def __post_init__(self) -> None:
        obs = tuple(self.observations)
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
        states, actions = np.asarray(states), np.asarray(actions)
        if states.shape != actions.shape or states.ndim != 1:
            raise ValueError(
                f"states and actions must be 1-D of equal length; got {states.shape} and "
                f"{actions.shape}"
            )
        mask = np.zeros(len(states), bool) if occluded is None else np.asarray(occluded, bool)
        obs = states * n_actions + actions
        return cls(observations=[None if m else int(o) for o, m in zip(obs, mask, strict=True)])


@dataclass(frozen=True)
class Trajectory:
    """Ground-truth states and actions of one demonstration, both shape (T,)."""

    states: np.ndarray = field(repr=False)
    actions: np.ndarray = field(repr=False)

    def __post_init__(self) -> None:
        s, a = np.asarray(self.states, dtype=np.int64), np.asarray(self.actions, dtype=np.int64)
        if s.shape != a.shape or s.ndim != 1:
            raise ValueError(
                f"states and actions must be 1-D of equal length; got {s.shape} and {a.shape}"
            )
        object.__setattr__(self, "states", s)
        object.__setattr__(self, "actions", a)

    def __len__(self) -> int:
        return len(self.states)


def check_demonstrations(demos, n_observations: int) -> list[Demonstration]:
    """Validate a collection of demonstrations against an observation space.

    Raises ``TypeError``/``ValueError`` naming the demonstration (and step) at fault.
    """
    if isinstance(demos, Demonstration):
        raise TypeError("demos must be a sequence of Demonstration; got a single Demonstration")
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
                f"demonstration {i}, step {t}: observation {obs[t]} is out of range for an "
                f"observation model with {n_observations} observations"
            )
    return demos


def pack_observations(demos: Sequence[Demonstration], n_observations: int) -> np.ndarray:
    """Stack demonstrations of one length into an array (N, T) with -1 for occluded steps.

    Raises ``ValueError`` naming the demonstration and step of an out-of-range observation.
    """
    lengths = {len(d) for d in demos}
    if len(lengths) != 1:
        raise ValueError(f"demonstrations packed together must share a length; got {lengths}")
    packed = np.stack([d.as_array() for d in demos])
    bad = np.argwhere(packed >= n_observations)
    if bad.size:
        i, t = bad[0]
        raise ValueError(
            f"demonstration {i}, step {t}: observation {packed[i, t]} is out of range for an "
            f"observation model with {n_observations} observations"
        )
    return packed


def sample_trajectory(
    mdp, policy: np.ndarray, length: int, seed=None, *, initial_state: int | None = None
) -> Trajectory:
    """Roll out a stochastic policy ``pi[s, a]`` for ``length`` steps.

    The first state is drawn from ``mdp.initial`` unless ``initial_state`` is given.
    """
    rng = check_random_state(seed)
    if length < 1:
        raise ValueError(f"length must be >= 1; got {length}")
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
    """
    rng = check_random_state(seed)
    if not 0.0 <= occlusion <= 1.0:
        raise ValueError(f"occlusion must be in [0, 1]; got {occlusion}")
    T = len(trajectory)
    n_hidden = round(occlusion * T)
    hidden = np.zeros(T, bool)
    hidden[rng.choice(T, size=n_hidden, replace=False)] = True
    probs = observation_model.probs
    obs: list[int | None] = []
    for t in range(T):
        if hidden[t]:
            obs.append(None)
        else:
            p = probs[trajectory.states[t], trajectory.actions[t]]
            obs.append(int(rng.choice(len(p), p=p)))
    return Demonstration(observations=obs)
