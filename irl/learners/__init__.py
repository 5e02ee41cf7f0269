"""IRL learners: MMAP-BIRL and the baselines MAP-BIRL, HiddenDataEM and MaxEnt IRL."""

from irl.learners.birl import MAPBIRL, MMAPBIRL
from irl.learners.maxent import HiddenDataEM, MaxEntIRL

__all__ = ["MAPBIRL", "MMAPBIRL", "HiddenDataEM", "MaxEntIRL"]
