"""Observation models ``O[s, a, o] = P(o | s, a)`` and the helpers that build them.

Layout: ``O[s, a, o]``; every ``O[s, a, :]`` sums to 1. An occluded step has no observation
and contributes a factor of 1 (it is not an observation of its own).

Observations that report a state-action pair use the index ``o = s * A + a``; observations
that report a state only use ``o = s``. States of a factored domain are indexed in row-major
(mixed-radix) order of their factors, the order ``np.ravel_multi_index`` uses.

The learners see the interface :class:`ObservationModel` only (the log-likelihood of an
observation over every hidden pair, and the pair it reports at face value). Implementations:

- :class:`DenseObservationModel`: the array ``O`` (``ObservationModel(probs)`` builds it);
- :class:`FactoredObservationModel`: per-factor confusion matrices, what calibration measures;
- :class:`SparseObservationModel`: a sparse matrix ``M[s * A + a, o]``;
- :class:`StateObservationModel`: a state confusion ``C[s, o]`` shared by every action.
"""

from irl.observation.base import ObservationModel, check_compatible
from irl.observation.builders import (
    factored_observation_model,
    identity_observation_model,
    pair_observation_model,
    state_observation_model,
)
from irl.observation.dense import DenseObservationModel
from irl.observation.factored import FactoredObservationModel
from irl.observation.sparse import SparseObservationModel, StateObservationModel

__all__ = [
    "DenseObservationModel",
    "FactoredObservationModel",
    "ObservationModel",
    "SparseObservationModel",
    "StateObservationModel",
    "check_compatible",
    "factored_observation_model",
    "identity_observation_model",
    "pair_observation_model",
    "state_observation_model",
]
