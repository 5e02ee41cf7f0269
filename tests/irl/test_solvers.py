import re

import numpy as np
import pytest
import scipy.sparse as sp

import irl
from irl.solvers import (
    OptimalQSolver,
    _bicgstab,
    _policy_operator,
    _PolicySystem,
    policy_values,
    solve_policy_derivatives,
)
from tests.irl.conftest import random_mdp


def value_iteration(mdp, reward, n_iter=3000):
    T = mdp.transitions
    V = np.zeros(mdp.n_states)
    for _ in range(n_iter):
        Q = reward + mdp.discount * np.einsum("sat,t->sa", T, V)
        V = Q.max(axis=1)
    return Q


@pytest.mark.parametrize("seed", range(5))
def test_policy_iteration_matches_value_iteration(seed):
    rng = np.random.default_rng(seed)
    mdp = random_mdp(rng, n_states=5, n_actions=3, n_features=2)
    theta = rng.normal(size=2)
    Q = OptimalQSolver(mdp).q_values(theta)
    np.testing.assert_allclose(Q, value_iteration(mdp, mdp.reward(theta)), atol=1e-8)


@pytest.mark.parametrize("seed", range(5))
def test_dq_is_the_derivative_of_q_star(seed):
    rng = np.random.default_rng(seed)
    mdp = random_mdp(rng, n_states=5, n_actions=3, n_features=3)
    theta = rng.normal(size=3)
    sol = OptimalQSolver(mdp).solve(theta)
    eps = 1e-6
    for k in range(3):
        e = np.eye(3)[k] * eps
        fd = (OptimalQSolver(mdp).q_values(theta + e) - OptimalQSolver(mdp).q_values(theta - e))
        np.testing.assert_allclose(sol.dQ[:, :, k], fd / (2 * eps), atol=1e-5)


def test_cached_region_gives_the_same_answer_as_a_fresh_solve():
    rng = np.random.default_rng(0)
    mdp = random_mdp(rng, n_states=6, n_actions=3, n_features=3)
    solver = OptimalQSolver(mdp)
    for _ in range(30):
        theta = rng.normal(size=3)
        np.testing.assert_allclose(solver.q_values(theta), OptimalQSolver(mdp).q_values(theta),
                                   atol=1e-9)
    assert solver.n_reuses_ > 0


def test_sparse_and_dense_give_the_same_solution():
    rng = np.random.default_rng(1)
    dense = random_mdp(rng, n_states=8, n_actions=3, n_features=2)
    sparse = irl.TabularMDP(
        transitions=[sp.csr_matrix(dense.transitions[:, a]) for a in range(3)],
        features=dense.features, discount=dense.discount, initial=dense.initial,
    )
    assert sparse.is_sparse and not dense.is_sparse
    theta = rng.normal(size=2)
    np.testing.assert_allclose(OptimalQSolver(sparse).q_values(theta),
                               OptimalQSolver(dense).q_values(theta), atol=1e-10)
    pol = OptimalQSolver(dense).solve(theta).policy
    np.testing.assert_allclose(policy_values(sparse, sparse.reward(theta), pol),
                               policy_values(dense, dense.reward(theta), pol), atol=1e-10)


def _grid(nx, ny, seed=0, discount=0.99):
    """A noisy nx x ny grid, 4 moves, sparse features: a long horizon, as in the bench."""
    return irl.domains.grid_mdp(nx, ny, seed=seed, discount=discount)


def _howard(mdp, theta):
    """Plain policy iteration from the reward's greedy policy, dense solves: the reference."""
    n, rows = mdp.n_states, np.arange(mdp.n_states)
    T = np.stack([mdp.next_state_distribution(s, a) for s in range(n)
                  for a in range(mdp.n_actions)]).reshape(n, mdp.n_actions, n)
    R = mdp.reward(theta)
    policy = np.argmax(R, axis=1)
    while True:
        dV = np.linalg.solve(np.eye(n) - mdp.discount * T[rows, policy],
                             mdp.features[rows, policy])
        dQ = mdp.features + mdp.discount * np.einsum("sat,tk->sak", T, dV)
        Q = dQ @ theta
        best = np.argmax(Q, axis=1)
        improve = Q[rows, best] > Q[rows, policy] + 1e-10 * (1 + np.abs(Q).max())
        if not improve.any():
            return policy, dQ
        policy = np.where(improve, best, policy)


SCHEDULES = [
    {},
    {"improvement_sweeps": 0},
    {"warm_start_sweeps": 0},
    {"warm_start_sweeps": 200, "sweep_patience": None, "improvement_sweeps": 0},
    {"sweep_patience": 1, "improvement_sweeps": 5},
    # sparse MDPs evaluate policies by BiCGSTAB: loosely, or falling back to factorizations
    {"krylov_min_states": 1},
    {"krylov_min_states": 1, "krylov_tol": 1e-2, "improvement_sweeps": 0},
    {"krylov_min_states": 1, "krylov_tol": 0.5, "improvement_sweeps": 0},
    {"krylov_min_states": 1, "krylov_max_iter": 2},
]


@pytest.mark.parametrize("kw", SCHEDULES)
def test_every_sweep_schedule_gives_the_optimal_policy_and_its_exact_derivatives(kw):
    mdp = _grid(12, 9)
    for theta in ([1.0, -1.0, 0.5, -0.5], [0.3, 2.0, -1.0, 0.1]):
        theta = np.array(theta)
        policy, dQ = _howard(mdp, theta)
        sol = OptimalQSolver(mdp, **kw).solve(theta)
        np.testing.assert_array_equal(sol.policy, policy)
        scale = np.abs(dQ).max()
        np.testing.assert_allclose(sol.dQ, dQ, rtol=0, atol=1e-10 * scale)
        np.testing.assert_allclose(sol.dQ, solve_policy_derivatives(mdp, sol.policy),
                                   rtol=0, atol=1e-10 * scale)


@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize("sparse", [False, True])
def test_sweep_schedules_agree_on_random_mdps(seed, sparse):
    rng = np.random.default_rng(seed)
    mdp = random_mdp(rng, n_states=int(rng.integers(2, 60)), n_actions=int(rng.integers(1, 5)),
                     n_features=3, sparse=sparse)
    theta = rng.normal(size=3)
    policy, dQ = _howard(mdp, theta)
    for kw in SCHEDULES:
        sol = OptimalQSolver(mdp, **kw).solve(theta)
        np.testing.assert_array_equal(sol.policy, policy)
        np.testing.assert_allclose(sol.dQ, dQ, rtol=0, atol=1e-10 * np.abs(dQ).max())


def test_ties_go_to_the_lowest_action():
    mdp = _grid(6, 5)
    for kw in SCHEDULES:
        sol = OptimalQSolver(mdp, **kw).solve(np.zeros(4))  # every action ties everywhere
        np.testing.assert_array_equal(sol.policy, 0)


def test_a_repeated_sparsity_pattern_reuses_the_ordering_exactly():
    """Every policy of the grid has the same P_pi pattern: the second factorization permutes
    by the first one's ordering; both solve as a dense solve does, as do action-dependent
    patterns (no reuse)."""
    rng = np.random.default_rng(3)
    for mdp in (_grid(7, 8), random_mdp(rng, n_states=30, n_actions=3, sparse=True)):
        system = _PolicySystem(mdp)
        rhs = rng.normal(size=(mdp.n_states, 2))
        for _ in range(4):
            policy = rng.integers(mdp.n_actions, size=mdp.n_states)
            P = mdp.policy_transitions(policy).toarray()
            expected = np.linalg.solve(np.eye(mdp.n_states) - mdp.discount * P, rhs)
            np.testing.assert_allclose(system.factor(policy)(rhs), expected, rtol=1e-12,
                                       atol=1e-12 * np.abs(expected).max())
        assert system._order is not None


def test_sweeps_after_an_evaluation_save_factorizations_on_a_long_horizon_grid(monkeypatch):
    mdp = _grid(40, 30)
    theta = np.array([1.0, -1.0, 0.5, -0.5])
    calls = []
    factor = _PolicySystem.factor
    monkeypatch.setattr(_PolicySystem, "factor",
                        lambda self, policy: calls.append(1) or factor(self, policy))
    counts, policies = [], []
    for kw in ({}, {"improvement_sweeps": 0}):
        calls.clear()
        sol = OptimalQSolver(mdp, krylov_min_states=None, **kw).solve(theta)
        np.testing.assert_allclose(sol.dQ, solve_policy_derivatives(mdp, sol.policy),
                                   rtol=0, atol=1e-10 * np.abs(sol.dQ).max())
        counts.append(len(calls) - 1)  # solve_policy_derivatives factors once more
        policies.append(sol.policy)
    np.testing.assert_array_equal(*policies)
    assert counts[0] < counts[1], counts  # 3 and 5 evaluations when written


def test_bicgstab_solves_a_policy_system_from_any_guess():
    rng = np.random.default_rng(0)
    mdp = _grid(15, 11)
    policy = rng.integers(mdp.n_actions, size=mdp.n_states)
    b = rng.normal(size=mdp.n_states)
    expected = _PolicySystem(mdp).factor(policy)(b[:, None])[:, 0]
    operator = _policy_operator(mdp, policy)
    for guess in (np.zeros_like(b), expected + rng.normal(size=b.shape)):
        x, n_iter, rate = _bicgstab(operator, b, guess, 1e-12 * np.linalg.norm(b), 1000)
        np.testing.assert_allclose(x, expected, rtol=0, atol=1e-9 * np.abs(expected).max())
        assert 0 < n_iter < 1000 and rate < 0.0
    x, n_iter, _ = _bicgstab(operator, b, np.zeros_like(b), 1e-12 * np.linalg.norm(b), 3)
    assert x is None and n_iter == 3  # not converged: no answer


def test_krylov_evaluations_factor_at_most_the_derivatives_and_agree_with_factored_ones(
        monkeypatch):
    """Every policy is evaluated by BiCGSTAB; the last one's derivatives are factored only
    where that is predicted to cost less (at this size it is)."""
    mdp = _grid(40, 30)
    calls = []
    factor = _PolicySystem.factor
    monkeypatch.setattr(_PolicySystem, "factor",
                        lambda self, policy: calls.append(1) or factor(self, policy))
    for theta in ([1.0, -1.0, 0.5, -0.5], [0.3, 2.0, -1.0, 0.1]):
        theta = np.array(theta)
        calls.clear()
        sol = OptimalQSolver(mdp, krylov_min_states=1000).solve(theta)
        assert len(calls) <= 1
        reference = OptimalQSolver(mdp, krylov_min_states=None).solve(theta)
        np.testing.assert_array_equal(sol.policy, reference.policy)
        np.testing.assert_allclose(sol.dQ, reference.dQ, rtol=0,
                                   atol=1e-12 * np.abs(reference.dQ).max())


@pytest.mark.parametrize("kw, error, words", [
    ({"max_iter": 0}, ValueError, "max_iter must be an integer >= 1; got 0"),
    ({"warm_start_sweeps": -1}, ValueError, "warm_start_sweeps must be an integer >= 0"),
    ({"sweep_patience": 0}, ValueError, "sweep_patience must be an integer >= 1"),
    ({"improvement_sweeps": 2.5}, TypeError, "improvement_sweeps must be an integer"),
    ({"krylov_min_states": 0}, ValueError, "krylov_min_states must be an integer >= 1"),
    ({"krylov_tol": 0.0}, ValueError, "krylov_tol must be in (0.0, 1.0)"),
    ({"krylov_tol": float("nan")}, ValueError, "krylov_tol must be in (0.0, 1.0)"),
    ({"krylov_max_iter": True}, TypeError, "krylov_max_iter must be an integer; got bool"),
    ({"cache_size": 0}, ValueError, "cache_size must be an integer >= 1"),
])
def test_bad_solver_options_are_refused_by_name(kw, error, words):
    with pytest.raises(error, match=re.escape(words)):
        OptimalQSolver(_grid(3, 3), **kw)
    with pytest.raises(TypeError, match="mdp must be a TabularMDP; got ndarray"):
        OptimalQSolver(np.zeros((3, 3)))
