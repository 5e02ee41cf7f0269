"""Helpers that build the common observation models from confusion matrices.

Layouts: ``C_S[s, s']``, ``C_A[a, a']``, ``C_f[true, observed]``; pair observations are indexed
``o = s' * A + a'``, state observations ``o = s'``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from irl._validation import as_float_array, check_int, check_probability_rows
from irl.observation.base import ObservationModel
from irl.observation.factored import FactoredObservationModel
from irl.observation.sparse import StateObservationModel

__all__ = [
    "factored_observation_model",
    "identity_observation_model",
    "pair_observation_model",
    "state_observation_model",
]


def identity_observation_model(n_states: int, n_actions: int) -> ObservationModel:
    """Noise-free observation of the pair: ``o = s * A + a`` with probability 1.

    With this model and no occlusion, MMAP-BIRL is exactly MAP-BIRL.

    Parameters
    ----------
    n_states, n_actions : int
        ``S`` and ``A``, each >= 1.

    Returns
    -------
    ObservationModel
        A :class:`~irl.observation.FactoredObservationModel` of identity confusions, with
        ``S * A`` observations.
    """
    n_states = check_int(n_states, "n_states", low=1)
    n_actions = check_int(n_actions, "n_actions", low=1)
    return FactoredObservationModel([np.eye(n_states)], np.eye(n_actions))


def pair_observation_model(
    state_confusion: np.ndarray, action_confusion: np.ndarray | None = None, *, n_actions=None
) -> ObservationModel:
    """Observations of the pair ``(s', a')`` with independent state and action confusion.

    ``O[s, a, s' * A + a'] = C_S[s, s'] * C_A[a, a']``, a
    :class:`~irl.observation.FactoredObservationModel` with one state factor.

    Parameters
    ----------
    state_confusion : ndarray of shape (S, S)
        ``C_S[s, s'] = P(observed state s' | true state s)``.
    action_confusion : ndarray of shape (A, A), optional
        ``C_A[a, a']``; the identity (actions observed exactly) when omitted, in which case
        ``n_actions`` is required.
    n_actions : int, optional
        ``A`` when ``action_confusion`` is omitted (keyword only).

    Returns
    -------
    ObservationModel
        A :class:`~irl.observation.FactoredObservationModel` with ``S * A`` observations.
    """
    C_S = as_float_array(state_confusion, "state_confusion")
    if C_S.ndim != 2 or C_S.shape[0] != C_S.shape[1] or C_S.shape[0] < 1:
        raise ValueError(f"state_confusion must be square (S, S) with S >= 1; got {C_S.shape}")
    check_probability_rows(C_S, "state_confusion")
    if action_confusion is None and n_actions is None:
        raise ValueError("give action_confusion or n_actions; got neither")
    return FactoredObservationModel([C_S], action_confusion,
                                    n_actions=None if action_confusion is not None else n_actions)


def state_observation_model(state_confusion, n_actions: int) -> ObservationModel:
    """Observations of the state only: ``O[s, a, o] = C_S[s, o]`` for every action.

    Parameters
    ----------
    state_confusion : ndarray or scipy.sparse matrix of shape (S, n_observations)
        ``C_S[s, o] = P(o | s)``; each row sums to 1. Square (``o = s'``, the state read) or
        not (observations of another kind, e.g. a detector's classes).
    n_actions : int
        ``A``: the actions are not observed.

    Returns
    -------
    ObservationModel
        A :class:`~irl.observation.StateObservationModel`.
    """
    return StateObservationModel(state_confusion, n_actions)


def factored_observation_model(
    factor_confusions: Sequence[np.ndarray], action_confusion: np.ndarray | None = None,
    *, n_actions: int | None = None,
) -> ObservationModel:
    """Pair observations from independent per-factor confusion matrices.

    The state is factored as ``s = ravel_multi_index((f_1, ..., f_F), sizes)``; each factor is
    observed through its own confusion matrix ``C_f[true, observed]``, so the state confusion is
    their Kronecker product. This is what perception calibration measures. The model never
    forms that product (:class:`~irl.observation.FactoredObservationModel`).

    Parameters
    ----------
    factor_confusions : sequence of ndarray, each of shape (n_f, n_f)
        ``C_f[true, observed]`` of each state factor, in the order of the state encoding.
    action_confusion : ndarray of shape (A, A), optional
        ``C_A[a, a']``; the identity when omitted, then ``n_actions`` is required.
    n_actions : int, optional
        ``A`` when ``action_confusion`` is omitted (keyword only).

    Returns
    -------
    FactoredObservationModel
        With ``prod_f n_f * A`` observations, ``o = s' * A + a'``.
    """
    return FactoredObservationModel(factor_confusions, action_confusion, n_actions=n_actions)
