"""IRL learners: MMAP-BIRL and the baselines MAP-BIRL, HiddenDataEM, MaxEnt IRL and behaviour
cloning, by name."""

from irl.learners.base import LearnerBase
from irl.learners.birl import MAPBIRL, MMAPBIRL
from irl.learners.cloning import BehaviorCloning
from irl.learners.maxent import HiddenDataEM, MaxEntIRL
from irl.learners.registry import (
    LEARNERS,
    LearnerSpec,
    make_estimator,
    register_learner,
    unregister_learner,
)

__all__ = [
    "LEARNERS",
    "MAPBIRL",
    "MMAPBIRL",
    "BehaviorCloning",
    "HiddenDataEM",
    "LearnerBase",
    "LearnerSpec",
    "MaxEntIRL",
    "make_estimator",
    "register_learner",
    "unregister_learner",
]
