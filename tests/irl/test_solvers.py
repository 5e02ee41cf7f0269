import numpy as np
import pytest
import scipy.sparse as sp

import irl
from irl.solvers import OptimalQSolver, policy_values
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
