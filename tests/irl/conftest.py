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


#: Every implementation of irl.ObservationModel; exactness tests run for each.
OM_KINDS = ("dense", "factored", "sparse", "state", "state-sparse")


def random_observation_model(rng, n_states, n_actions, n_obs=4, kind="dense") -> ObservationModel:
    """A random observation model of the given implementation.

    ``factored`` has pair observations (``n_obs`` is ignored: S * A of them) through one or two
    state factors; ``sparse`` has structural zeros (every row and column keeps its largest
    entry, so no observation is impossible under every pair); ``state``/``state-sparse`` observe
    the state only, through a dense or a ``scipy.sparse`` confusion.
    """
    import scipy.sparse as sp

    from irl.observation import (
        FactoredObservationModel,
        SparseObservationModel,
        StateObservationModel,
    )

    if kind == "dense":
        return ObservationModel(rng.dirichlet(np.ones(n_obs), size=(n_states, n_actions)))
    if kind == "factored":
        sizes = (2, n_states // 2) if n_states > 2 and n_states % 2 == 0 else (n_states,)
        return FactoredObservationModel(
            [rng.dirichlet(np.ones(n), size=n) for n in sizes],
            rng.dirichlet(np.ones(n_actions), size=n_actions),
        )
    if kind == "sparse":
        M = rng.dirichlet(np.ones(n_obs), size=n_states * n_actions)
        row_max, col_max = M.max(axis=1, keepdims=True), M.max(axis=0)
        keep = (M >= 0.2) | (row_max <= M) | (col_max <= M)
        M = np.where(keep, M, 0.0)
        M /= M.sum(axis=1, keepdims=True)
        return SparseObservationModel(sp.csr_matrix(M), n_actions)
    if kind in ("state", "state-sparse"):
        C = rng.dirichlet(np.ones(n_obs), size=n_states)
        return StateObservationModel(sp.csr_matrix(C) if kind == "state-sparse" else C,
                                     n_actions)
    raise ValueError(f"kind must be one of {OM_KINDS}; got {kind!r}")


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


def brute_force_log(mdp, log_pi, om, demo):
    """``log P(o)`` and the marginals ``P(s_t, a_t | o)`` by enumerating all sequences with
    every product kept in log space, for policies far too peaked for :func:`brute_force`
    (``log_pi[s, a]``)."""
    from scipy.special import logsumexp

    S, A = mdp.n_states, mdp.n_actions
    with np.errstate(divide="ignore"):
        log_T, log_O, log_p0 = np.log(mdp.transitions), np.log(om.probs), np.log(mdp.initial)
    obs = demo.observations
    L = len(obs)
    seqs = np.array(list(itertools.product(range(S * A), repeat=L)))
    s, a = seqs // A, seqs % A
    terms = log_p0[s[:, 0]] + log_pi[s, a].sum(axis=1)
    for t in range(L):
        if obs[t] is not None:
            terms = terms + log_O[s[:, t], a[:, t], obs[t]]
        if t + 1 < L:
            terms = terms + log_T[s[:, t], a[:, t], s[:, t + 1]]
    total = float(logsumexp(terms))
    marg = np.zeros((L, S, A))
    if not np.isfinite(total):  # an impossible demonstration: no marginals
        return total, marg
    for t in range(L):
        for x in range(S * A):
            hit = seqs[:, t] == x
            if hit.any():
                marg[t, x // A, x % A] = np.exp(logsumexp(terms[hit]) - total)
    return total, marg


def pytest_terminal_summary(terminalreporter):
    """Report the fuzzing tally of tests/irl/test_fuzz.py when it ran."""
    import sys

    fuzz = sys.modules.get("tests.irl.test_fuzz")
    tally = getattr(fuzz, "TALLY", None)
    if not tally or not (tally["bad"] or tally["edge"]):
        return
    terminalreporter.write_line(
        f"irl API fuzzing: {tally['bad']} bad inputs tried, {tally['bad_clear']} answered by a "
        f"one-line ValueError/TypeError naming the argument; {tally['edge']} legal edge cases "
        f"tried, {tally['edge_ok']} worked or were refused by name"
    )
