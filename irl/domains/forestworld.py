"""Forestworld (Bogert & Doshi; the paper's Fig. 1): a fugitive crosses a 4x4 forest.

States are sectors ``(x, y)`` with 0-based coordinates, ``s = x * 4 + y``. Actions N (y + 1),
E (x + 1), S (y - 1), W (x - 1): the intended sector with probability 0.9, each of the other
three directions with 0.1 / 3; a move into the edge stays put. Features (on the current
sector): Avoidable_state(1, 1), Avoidable_state(3, 2), Goal_state(3, 3). The fugitive starts in
any sector other than those three, uniformly.

The UAV observes the sector and the move. Through a hidden tunnel from (2, 3) to (3, 3), a
fugitive at the goal (3, 3) is reported at (2, 3) with probability ``noise`` (30% in the paper).
"""

from __future__ import annotations

import numpy as np

from irl._validation import check_real
from irl.domains.base import Domain
from irl.domains.task import TaskDescription
from irl.mdp import TabularMDP
from irl.observation import pair_observation_model
from irl.priors import GaussianPrior

__all__ = ["ACTIONS", "FORESTWORLD_TASK", "GRID", "forestworld", "sector"]

GRID = 4
ACTIONS = {"north": (0, 1), "east": (1, 0), "south": (0, -1), "west": (-1, 0)}
AVOIDABLE = ((1, 1), (3, 2))
GOAL = (3, 3)
TUNNEL = (2, 3)
FEATURE_NAMES = ("avoidable_state(1,1)", "avoidable_state(3,2)", "goal_state(3,3)")

#: Forestworld as data: factors ``x`` then ``y`` (``s = x * 4 + y``, so ``x`` is the most
#: significant), values named by their coordinate. The task names states ``"(x, y)"``; the MDP
#: keeps its compact ``"(x,y)"``.
FORESTWORLD_TASK = TaskDescription(
    name="forestworld",
    factors={"x": tuple(str(i) for i in range(GRID)), "y": tuple(str(i) for i in range(GRID))},
    action_names=tuple(ACTIONS),
    feature_names=FEATURE_NAMES,
)

#: High negative on the avoidable sectors, high positive on the goal, on the scale of the paper's
#: prior N(-1, 0.5). With beta = 1.5 the fugitive takes its greedy move about 77% of the time.
#: Only beta * theta is identifiable; see docs/paper-errata.md on the paper's beta = 0.03.
TRUE_THETA = np.array([-2.0, -2.0, 2.0])


def sector(x: int, y: int) -> int:
    """State index of sector (x, y).

    Parameters
    ----------
    x, y : int
        The sector's coordinates, each in ``[0, GRID)``.

    Returns
    -------
    int
        ``x * GRID + y``.
    """
    if not (0 <= x < GRID and 0 <= y < GRID):
        raise ValueError(f"sector ({x}, {y}) is outside the {GRID}x{GRID} grid")
    return x * GRID + y


def _transitions(success: float) -> np.ndarray:
    n = GRID * GRID
    moves = list(ACTIONS.values())
    T = np.zeros((n, len(moves), n))
    for x in range(GRID):
        for y in range(GRID):
            s = sector(x, y)
            for a in range(len(moves)):
                for b, (dx, dy) in enumerate(moves):
                    p = success if a == b else (1.0 - success) / (len(moves) - 1)
                    nx, ny = x + dx, y + dy
                    if not (0 <= nx < GRID and 0 <= ny < GRID):
                        nx, ny = x, y
                    T[s, a, sector(nx, ny)] += p
    return T


def _features() -> np.ndarray:
    n = GRID * GRID
    phi = np.zeros((n, len(ACTIONS), 3))
    for k, cell in enumerate((*AVOIDABLE, GOAL)):
        phi[sector(*cell), :, k] = 1.0
    return phi


def tunnel_confusion(noise: float) -> np.ndarray:
    """``C[s, s']``: the goal is seen at the tunnel entrance with probability ``noise``."""
    noise = check_real(noise, "noise", low=0.0, high=1.0)
    C = np.eye(GRID * GRID)
    C[sector(*GOAL), sector(*GOAL)] = 1.0 - noise
    C[sector(*GOAL), sector(*TUNNEL)] = noise
    return C


def forestworld(
    *, noise: float = 0.3, success: float = 0.9, discount: float = 0.99, beta: float = 1.5
) -> Domain:
    """The Forestworld domain with the paper's settings (prior mean -1, variance 0.5).

    Parameters
    ----------
    noise : float
        Probability that a fugitive at the goal is reported at the tunnel entrance (2, 3).
    success : float
        Probability that a move goes where intended.
    discount, beta : float
        gamma = 0.99 as in the paper; beta is the fugitive's Boltzmann rationality.

    Returns
    -------
    Domain
        With the true weights :data:`TRUE_THETA`, the prior ``N(-1, 0.5)`` per weight and
        the task :data:`FORESTWORLD_TASK`.
    """
    success = check_real(success, "success", low=0.0, high=1.0)
    beta = check_real(beta, "beta", low=0.0, low_open=True)
    noise = check_real(noise, "noise", low=0.0, high=1.0)
    initial = np.ones(GRID * GRID)
    for cell in (*AVOIDABLE, GOAL):
        initial[sector(*cell)] = 0.0
    initial /= initial.sum()
    mdp = TabularMDP(
        transitions=_transitions(success),
        features=_features(),
        discount=discount,
        initial=initial,
        state_names=[f"({x},{y})" for x in range(GRID) for y in range(GRID)],
        action_names=list(ACTIONS),
        feature_names=list(FEATURE_NAMES),
    )
    return Domain(
        name="forestworld",
        mdp=mdp,
        true_theta=TRUE_THETA.copy(),
        observation_model=pair_observation_model(tunnel_confusion(noise), n_actions=len(ACTIONS)),
        beta=beta,
        prior=GaussianPrior(mean=-1.0, std=np.sqrt(0.5)),
        task=FORESTWORLD_TASK,
    )
