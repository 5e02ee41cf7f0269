"""irl: inverse reinforcement learning from occluded, noisy demonstrations.

Exact MMAP-BIRL (marginal MAP Bayesian IRL under occlusion with observer noise) and the
baselines MAP-BIRL, HiddenDataEM and MaxEnt IRL, on tabular MDPs with linear rewards, and
behaviour cloning (``BehaviorCloning``), which copies the actions and learns no reward.

>>> import irl
>>> dom = irl.domains.forestworld(noise=0.3)
>>> demos, _ = dom.sample(n=5, length=15, occlusion=0.2, seed=0)
>>> est = irl.MMAPBIRL(dom.mdp, dom.observation_model, beta=dom.beta, prior=dom.prior, seed=0)
>>> est = est.fit(demos)
>>> est.theta_.shape
(3,)
"""

from irl import domains
from irl.demonstrations import Demonstration, Trajectory
from irl.domains import Domain, TaskDescription
from irl.exceptions import ConvergenceWarning, NotFittedError
from irl.learners import (
    LEARNERS,
    MAPBIRL,
    MMAPBIRL,
    BehaviorCloning,
    HiddenDataEM,
    LearnerSpec,
    MaxEntIRL,
    make_estimator,
    register_learner,
)
from irl.mdp import TabularMDP
from irl.metrics import (
    inverse_learning_error,
    normalized_inverse_learning_error,
    policy_mismatch,
    reward_distance,
)
from irl.observation import (
    DenseObservationModel,
    FactoredObservationModel,
    ObservationModel,
    SparseObservationModel,
    StateObservationModel,
    factored_observation_model,
    identity_observation_model,
    pair_observation_model,
    state_observation_model,
)
from irl.priors import GaussianPrior

__all__ = [
    "LEARNERS",
    "MAPBIRL",
    "MMAPBIRL",
    "BehaviorCloning",
    "ConvergenceWarning",
    "Demonstration",
    "DenseObservationModel",
    "Domain",
    "FactoredObservationModel",
    "GaussianPrior",
    "HiddenDataEM",
    "LearnerSpec",
    "MaxEntIRL",
    "NotFittedError",
    "ObservationModel",
    "SparseObservationModel",
    "StateObservationModel",
    "TabularMDP",
    "TaskDescription",
    "Trajectory",
    "domains",
    "factored_observation_model",
    "identity_observation_model",
    "inverse_learning_error",
    "make_estimator",
    "normalized_inverse_learning_error",
    "pair_observation_model",
    "policy_mismatch",
    "register_learner",
    "reward_distance",
    "state_observation_model",
]
