"""Tiny random models and a brute-force oracle that enumerates every hidden sequence."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import irl
from irl.observation import ObservationModel


def random_mdp(rng, n_states=3, n_actions=2, n_features=2, sparse=False) -> irl.TabularMDP:
    T = rng.dirichlet(np.ones(n_states) * 0.7, size=(n_states, n_actions))
    phi = rng.normal(size=(n_states, n_actions, n_features))
    p0 = rng.dirichlet(np.ones(n_states))
    if sparse:
        import scipy.sparse as sp

        return irl.TabularMDP(
            transitions=[sp.csr_matrix(T[:, a, :]) for a in range(n_actions)],
            features=phi, discount=0.9, initial=p0,
        )
    return irl.TabularMDP(transitions=T, features=phi, discount=0.9, initial=p0)


def random_observation_model(rng, n_states, n_actions, n_obs=4) -> ObservationModel:
    return ObservationModel(rng.dirichlet(np.ones(n_obs), size=(n_states, n_actions)))


def random_demo(rng, length, n_obs, p_occluded=0.4) -> irl.Demonstration:
    return irl.Demonstration(
        observations=[None if rng.random() < p_occluded else int(rng.integers(n_obs))
                      for _ in range(length)]
    )


def brute_force(mdp, pi, om, demo):
    """``log P(o)`` and the marginals ``P(s_t, a_t | o)`` by enumerating all sequences.

    ``pi`` is ``pi[s, a]`` or ``pi[t, s, a]``.
    """
    S, A = mdp.n_states, mdp.n_actions
    T = mdp.transitions
    obs = demo.observations
    L = len(obs)
    pis = np.broadcast_to(pi, (L, S, A)) if pi.ndim == 2 else pi
    total = 0.0
    marg = np.zeros((L, S, A))
    for seq in itertools.product(range(S * A), repeat=L):
        s = [x // A for x in seq]
        a = [x % A for x in seq]
        p = mdp.initial[s[0]]
        for t in range(L):
            p *= pis[t, s[t], a[t]]
            if obs[t] is not None:
                p *= om.probs[s[t], a[t], obs[t]]
            if t + 1 < L:
                p *= T[s[t], a[t], s[t + 1]]
        total += p
        for t in range(L):
            marg[t, s[t], a[t]] += p
    return np.log(total), marg / total


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
