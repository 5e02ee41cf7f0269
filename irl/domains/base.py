"""A benchmark domain: an MDP, the expert's true reward, and how the expert is observed."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from irl._random import check_random_state
from irl._validation import check_int, check_real
from irl.demonstrations import Demonstration, Trajectory, observe, sample_trajectory
from irl.domains.task import TaskDescription
from irl.mdp import TabularMDP
from irl.observation import ObservationModel, check_compatible
from irl.priors import GaussianPrior
from irl.solvers import OptimalQSolver, boltzmann_policy

__all__ = ["Domain"]


@dataclass(frozen=True)
class Domain:
    """Everything needed to generate and score IRL data on one problem.

    Attributes
    ----------
    name : str
    mdp : TabularMDP
    true_theta : ndarray of shape (K,)
        The expert's reward weights.
    observation_model : ObservationModel
        How the learner's sensor sees the expert's ``(s, a)``.
    beta : float
        Boltzmann rationality of the expert: ``pi(a|s) = softmax_a(beta * Q*(s, a))``.
    prior : GaussianPrior
        The prior the paper uses on this domain.
    task : TaskDescription or None
        The names and encodings of the domain's factored states, for applications; ``None`` for
        a domain without factors. When given, its sizes and its action and feature names must
        match ``mdp`` (state names may be spelled differently in ``mdp``).
    """

    name: str
    mdp: TabularMDP
    true_theta: np.ndarray
    observation_model: ObservationModel
    beta: float
    prior: GaussianPrior
    task: TaskDescription | None = None

    def __post_init__(self) -> None:
        task = self.task
        if task is None:
            return
        if not isinstance(task, TaskDescription):
            raise TypeError(f"task must be a TaskDescription or None; got {type(task).__name__}")
        mdp = self.mdp
        if (task.n_states, task.n_actions, task.n_features) != (
            mdp.n_states, mdp.n_actions, mdp.n_features
        ):
            raise ValueError(
                f"task must match mdp in (n_states, n_actions, n_features) = "
                f"{(mdp.n_states, mdp.n_actions, mdp.n_features)}; got "
                f"{(task.n_states, task.n_actions, task.n_features)}"
            )
        for attr in ("action_names", "feature_names"):
            if tuple(getattr(mdp, attr)) != getattr(task, attr):
                raise ValueError(
                    f"task.{attr} must equal mdp.{attr} {tuple(getattr(mdp, attr))}; got "
                    f"{getattr(task, attr)}"
                )

    @property
    def state_names(self) -> list[str]:
        return self.mdp.state_names

    @property
    def action_names(self) -> list[str]:
        return self.mdp.action_names

    @property
    def feature_names(self) -> list[str]:
        return self.mdp.feature_names

    def expert_policy(self) -> np.ndarray:
        """The expert's stochastic policy ``pi[s, a]`` under the true reward."""
        Q = OptimalQSolver(self.mdp).q_values(self.true_theta)
        return boltzmann_policy(Q, self.beta)

    def optimal_policy(self) -> np.ndarray:
        """The expert's greedy optimal policy ``policy[s] -> a``."""
        return OptimalQSolver(self.mdp).solve(self.true_theta).policy

    def sample(
        self, n: int, length: int, occlusion: float = 0.0, seed=None,
        observation_model: ObservationModel | None = None,
    ) -> tuple[list[Demonstration], list[Trajectory]]:
        """Sample ``n`` expert trajectories and observe them.

        Each demonstration has ``round(occlusion * length)`` occluded steps at random positions;
        the others are observed through ``observation_model`` (the domain's by default).

        Returns
        -------
        demos : list of Demonstration
            What the learner sees.
        trajectories : list of Trajectory
            The ground truth behind each demonstration.
        """
        n = check_int(n, "n", low=1)
        length = check_int(length, "length", low=1)
        occlusion = check_real(occlusion, "occlusion", low=0.0, high=1.0)
        rng = check_random_state(seed)
        om = self.observation_model if observation_model is None else observation_model
        check_compatible(self.mdp, om)
        policy = self.expert_policy()
        trajectories = [sample_trajectory(self.mdp, policy, length, rng) for _ in range(n)]
        demos = [observe(tr, om, occlusion, rng) for tr in trajectories]
        return demos, trajectories
