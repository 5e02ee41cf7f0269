"""The paper's benchmark domains: Forestworld and onion sorting, and tasks described as data;
and a sparse grid world for tests of scale."""

from irl.domains.base import Domain
from irl.domains.forestworld import FORESTWORLD_TASK, forestworld
from irl.domains.grid import grid_mdp
from irl.domains.onion_sorting import SORTING_TASK, onion_sorting
from irl.domains.task import TaskDescription

__all__ = [
    "FORESTWORLD_TASK",
    "SORTING_TASK",
    "Domain",
    "TaskDescription",
    "forestworld",
    "grid_mdp",
    "onion_sorting",
]
