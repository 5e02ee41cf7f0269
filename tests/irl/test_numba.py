"""The compiled scaled forward-backward kernel (irl/_numba.py) computes what the numpy pass
computes, and declines (``ok`` False) where the numpy pass would hand over to the log space;
its separable entry point, given a model's state and action parts, computes what it computes
given their product."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

import irl
from irl import _numba
from irl.inference import (
    PosteriorStats,
    forward_backward,
    observation_factors,
    pack_demonstrations,
    posterior_stats,
)
from irl.inference.scaled import _scaled_floor
from irl.observation import FactoredObservationModel, StateObservationModel
from tests.irl.conftest import OM_KINDS, random_demo, random_mdp, random_observation_model

pytest.importorskip("numba")

MDP_KINDS = ("dense", "sparse", "dense-mostly-zero")


def make_mdp(rng, kind, n_states=6, n_actions=3):
    """A random MDP: dense T, sparse T, or a dense T of few nonzeros (whose numpy products go
    through CSR)."""
    if kind != "dense-mostly-zero":
        return random_mdp(rng, n_states, n_actions, sparse=kind == "sparse")
    T = np.zeros((n_states, n_actions, n_states))
    for s in range(n_states):
        for a in range(n_actions):
            nxt = rng.choice(n_states, size=2, replace=False)
            T[s, a, nxt] = rng.dirichlet(np.ones(2))
    return irl.TabularMDP(transitions=T, features=rng.normal(size=(n_states, n_actions, 2)),
                          discount=0.9, initial=rng.dirichlet(np.ones(n_states)))


def kernel(mdp, log_pi, factors, lengths, p0=None):
    """One batch through the kernel, arguments as the numpy pass builds them."""
    p0 = np.exp(mdp.log_initial) if p0 is None else p0
    return _numba.scaled_forward_backward(
        *_numba.operator_arrays(mdp._action_major), np.exp(log_pi.T), factors.factor,
        factors.shift, lengths, p0, _scaled_floor(mdp))


def kernel_stats(mdp, log_pi, packed) -> PosteriorStats:
    """:func:`posterior_stats` of a packing through the kernel (every batch must pass)."""
    n, S, A = packed.n_demos, mdp.n_states, mdp.n_actions
    ll, occ, init = np.empty(n), np.empty((n, S, A)), np.empty((n, S))
    for idx, obs, lengths, factors in zip(packed.batches, packed.obs, packed.lengths,
                                          packed.factors, strict=True):
        factors = factors or observation_factors(packed.observation_model, obs)
        ok, ll[idx], occ[idx], init[idx] = kernel(mdp, log_pi, factors, lengths)
        assert ok
    return PosteriorStats(log_likelihood=ll, occupancy=occ, initial=init)


def assert_same(got: PosteriorStats, want: PosteriorStats, atol: float = 0.0) -> None:
    """Equal to rounding: relative 1e-12 (the log-likelihood of an all-occluded demonstration
    is 0 up to a few ulps of 1, hence its absolute tolerance)."""
    np.testing.assert_allclose(got.log_likelihood, want.log_likelihood, rtol=1e-12,
                               atol=max(atol, 1e-14))
    np.testing.assert_allclose(got.occupancy, want.occupancy, rtol=1e-12, atol=atol)
    np.testing.assert_allclose(got.initial, want.initial, rtol=1e-12, atol=atol)


def test_available():
    assert _numba.available()


@pytest.mark.parametrize("om_kind", OM_KINDS)
@pytest.mark.parametrize("mdp_kind", MDP_KINDS)
def test_kernel_equals_the_numpy_pass_on_a_ragged_padded_batch(mdp_kind, om_kind):
    rng = np.random.default_rng(MDP_KINDS.index(mdp_kind) * 10 + OM_KINDS.index(om_kind))
    mdp = make_mdp(rng, mdp_kind)
    om = random_observation_model(rng, mdp.n_states, mdp.n_actions, n_obs=5, kind=om_kind)
    log_pi = np.log(rng.dirichlet(np.ones(mdp.n_actions), size=mdp.n_states))
    demos = [random_demo(rng, n, om.n_observations, p_occluded=0.3)
             for n in (9, 8, 1, 9, 7, 9)]
    packed = pack_demonstrations(demos, om)
    assert any(len(set(lens.tolist())) > 1 for lens in packed.lengths)  # ragged and padded
    got = kernel_stats(mdp, log_pi, packed)
    assert_same(got, posterior_stats(mdp, log_pi, packed, method="auto"))
    np.testing.assert_allclose(got.occupancy.sum(axis=(1, 2)), [len(d) for d in demos],
                               rtol=1e-12)
    assert got.occupancy.flags.c_contiguous and got.occupancy.dtype == np.float64


@pytest.mark.parametrize("mdp_kind", MDP_KINDS)
def test_kernel_equals_forward_backward_on_one_batch(mdp_kind):
    rng = np.random.default_rng(7)
    mdp = make_mdp(rng, mdp_kind, n_states=8, n_actions=2)
    om = random_observation_model(rng, 8, 2, n_obs=6, kind="dense")
    log_pi = np.log(rng.dirichlet(np.ones(2), size=8))
    obs = rng.integers(-1, 6, size=(4, 40))
    obs[1, 25:] = -1  # a padded demonstration
    lengths = np.array([40, 25, 40, 40])
    ok, ll, occ, init = kernel(mdp, log_pi, observation_factors(om, obs), lengths)
    assert ok
    assert_same(PosteriorStats(ll, occ, init),
                forward_backward(mdp, log_pi, obs, om, lengths=lengths, method="auto"))


def test_kernel_equals_the_numpy_pass_on_the_sorting_domain():
    dom = irl.domains.onion_sorting(noise=0.3)
    demos, _ = dom.sample(6, 15, occlusion=0.3, seed=3)
    packed = pack_demonstrations(demos, dom.observation_model)
    log_pi = np.log(dom.expert_policy())
    assert_same(kernel_stats(dom.mdp, log_pi, packed),
                posterior_stats(dom.mdp, log_pi, packed, method="auto"))


def chain(n_states=3):
    """Action 0 stays, action 1 moves one state right (the last state stays): transition
    probabilities 1, so ``F`` is about 344."""
    T = np.zeros((n_states, 2, n_states))
    T[np.arange(n_states), 0, np.arange(n_states)] = 1.0
    T[np.arange(n_states), 1, np.minimum(np.arange(n_states) + 1, n_states - 1)] = 1.0
    p0 = np.zeros(n_states)
    p0[0] = 1.0
    return irl.TabularMDP(transitions=T, features=np.ones((n_states, 2, 1)), discount=0.9,
                          initial=p0)


def test_a_predicted_probability_below_the_floor_fails_the_range_check():
    # pi(move) = e^-300 passes the caller's check (log_pi_min >= -F), but two moves in a row
    # predict e^-600 < e^-F for the last state: the numpy pass hands over to the log space.
    mdp = chain()
    log_pi = np.tile([np.log1p(-np.exp(-300.0)), -300.0], (3, 1))
    om = irl.ObservationModel(np.full((3, 2, 2), 0.5))
    obs = np.full((2, 4), -1)
    factors = observation_factors(om, obs)
    assert factors.min_log + log_pi.min() >= -_scaled_floor(mdp)
    ok = kernel(mdp, log_pi, factors, np.array([4, 4]))[0]
    assert not ok
    # one step predicts nothing, two steps only e^-300: in range
    ok, ll, occ, init = kernel(mdp, log_pi, factors, np.array([2, 1]))
    assert ok
    assert_same(PosteriorStats(ll, occ, init),  # the log pass sums log(1 - e^-300) terms
                forward_backward(mdp, log_pi, obs[:, :2], om, lengths=np.array([2, 1]),
                                 method="log"), atol=1e-15)


def test_an_initial_probability_below_the_floor_fails_the_range_check():
    mdp = chain()
    log_pi = np.log(np.full((3, 2), 0.5))
    factors = observation_factors(irl.ObservationModel(np.full((3, 2, 2), 0.5)),
                                  np.full((1, 2), -1))
    p0 = np.array([1.0, 1e-200, 0.0])
    assert not kernel(mdp, log_pi, factors, np.array([2]), p0=p0)[0]


def test_an_impossible_observation_fails():
    # observation 1 only comes from state 2, which the chain cannot reach in one step
    mdp = chain()
    log_pi = np.log(np.full((3, 2), 0.5))
    probs = np.zeros((3, 2, 2))
    probs[:, :, 0] = 1.0
    probs[2, :, :] = [0.5, 0.5]
    om = irl.ObservationModel(probs)
    obs = np.array([[-1, 1], [0, 0]])
    factors = observation_factors(om, obs)
    assert factors.possible  # possible under some pair, but not after step 0
    assert not kernel(mdp, log_pi, factors, np.array([2, 2]))[0]
    with pytest.raises(ValueError, match="impossible"):
        forward_backward(mdp, log_pi, obs, om, method="auto")
    # an observation no pair emits: factor undefined (NaN), shift -inf
    probs[2, :, :] = [1.0, 0.0]
    om = irl.ObservationModel(probs)
    factor, shift, _ = om.scaled_likelihoods(obs, action_major=True)
    assert np.isneginf(shift[0, 1])
    ok = _numba.scaled_forward_backward(*_numba.operator_arrays(mdp._action_major),
                                        np.exp(log_pi.T), factor, shift, np.array([2, 2]),
                                        mdp.initial, _scaled_floor(mdp))[0]
    assert not ok


@pytest.mark.parametrize("om_kind", ["sparse", "factored"])
def test_scattered_and_gathered_pushes_are_the_same_sums(om_kind, monkeypatch):
    rng = np.random.default_rng(3)
    mdp = make_mdp(rng, "dense-mostly-zero", n_states=8, n_actions=3)
    om = random_observation_model(rng, 8, 3, n_obs=6, kind=om_kind)
    log_pi = np.log(rng.dirichlet(np.ones(3), size=8))
    obs = np.array([random_demo(rng, 30, om.n_observations, 0.2).as_array()
                    for _ in range(3)])
    factors = observation_factors(om, obs)
    runs = []
    for fraction in (0.0, 2.0):  # always gather, always scatter
        monkeypatch.setattr(_numba, "_SCATTER_FRACTION", fraction)
        runs.append(kernel(mdp, log_pi, factors, np.array([30, 30, 30])))
    for gathered, scattered in zip(*runs, strict=True):
        np.testing.assert_array_equal(gathered, scattered)
    assert runs[0][0]


# -- the separable entry point ------------------------------------------------------------

#: The kinds of random_observation_model whose likelihoods are separable.
SEPARABLE_KINDS = ("factored", "state")


def separable_kernel(mdp, log_pi, om, obs, lengths, p0=None):
    """One batch through the separable kernel, its parts from ``om.separable_likelihoods``."""
    state, action, shift, _ = om.separable_likelihoods(obs)
    p0 = np.exp(mdp.log_initial) if p0 is None else p0
    return _numba.scaled_forward_backward_separable(
        *_numba.operator_arrays(mdp._action_major), np.exp(log_pi.T), state, action, shift,
        lengths, p0, _scaled_floor(mdp))


def product_kernel(mdp, log_pi, om, obs, lengths, p0=None):
    """The same batch through the full kernel, given the parts' product as numpy forms it."""
    state, action, shift, _ = om.separable_likelihoods(obs)
    p0 = np.exp(mdp.log_initial) if p0 is None else p0
    return _numba.scaled_forward_backward(
        *_numba.operator_arrays(mdp._action_major), np.exp(log_pi.T),
        action[..., :, None] * state[..., None, :], shift, lengths, p0, _scaled_floor(mdp))


def both_kernels(mdp, log_pi, om, obs, lengths, p0=None):
    """The separable kernel's result, checked bit for bit against the full kernel's given the
    product (``ok`` included)."""
    got = separable_kernel(mdp, log_pi, om, obs, lengths, p0)
    want = product_kernel(mdp, log_pi, om, obs, lengths, p0)
    assert got[0] == want[0]
    if got[0]:
        for g, w in zip(got[1:], want[1:], strict=True):
            np.testing.assert_array_equal(g, w)
    return got


@pytest.mark.parametrize("om_kind", SEPARABLE_KINDS)
@pytest.mark.parametrize("mdp_kind", MDP_KINDS)
def test_separable_kernel_equals_the_full_kernel_and_the_numpy_pass(mdp_kind, om_kind):
    rng = np.random.default_rng(100 + MDP_KINDS.index(mdp_kind) * 10
                                + SEPARABLE_KINDS.index(om_kind))
    mdp = make_mdp(rng, mdp_kind)
    om = random_observation_model(rng, mdp.n_states, mdp.n_actions, n_obs=5, kind=om_kind)
    log_pi = np.log(rng.dirichlet(np.ones(mdp.n_actions), size=mdp.n_states))
    demos = [random_demo(rng, n, om.n_observations, p_occluded=0.3)
             for n in (9, 8, 1, 9, 7, 9)]
    assert sum(d.n_occluded for d in demos) >= 5
    packed = pack_demonstrations(demos, om)
    assert any(len(set(lens.tolist())) > 1 for lens in packed.lengths)  # ragged and padded
    n, S, A = packed.n_demos, mdp.n_states, mdp.n_actions
    ll, occ, init = np.empty(n), np.empty((n, S, A)), np.empty((n, S))
    for idx, obs, lengths in zip(packed.batches, packed.obs, packed.lengths, strict=True):
        ok, ll[idx], occ[idx], init[idx] = both_kernels(mdp, log_pi, om, obs, lengths)
        assert ok
    got = PosteriorStats(log_likelihood=ll, occupancy=occ, initial=init)
    assert_same(got, kernel_stats(mdp, log_pi, packed))  # the full kernel on its own factors
    assert_same(got, posterior_stats(mdp, log_pi, packed, method="auto"))


def test_separable_kernel_scatters_and_gathers_as_the_full_kernel(monkeypatch):
    rng = np.random.default_rng(5)
    mdp = make_mdp(rng, "dense-mostly-zero", n_states=8, n_actions=3)
    om = random_observation_model(rng, 8, 3, kind="factored")
    log_pi = np.log(rng.dirichlet(np.ones(3), size=8))
    obs = np.array([random_demo(rng, 30, om.n_observations, 0.2).as_array()
                    for _ in range(3)])
    for fraction in (0.0, 2.0):  # always gather, always scatter
        monkeypatch.setattr(_numba, "_SCATTER_FRACTION", fraction)
        assert both_kernels(mdp, log_pi, om, obs, np.array([30, 21, 30]))[0]


def chain_model(kind, confusion):
    """A separable model of the chain's states observed through ``confusion`` (3 x 3; actions
    through a blind action sensor by the factored one), and its encoding of an observed state."""
    if kind == "state":
        return StateObservationModel(confusion, 2), lambda o: o
    return (FactoredObservationModel([confusion], np.full((2, 2), 0.5)),
            lambda o: -1 if o < 0 else 2 * o)


@pytest.mark.parametrize("om_kind", SEPARABLE_KINDS)
def test_separable_kernel_fails_the_range_checks_of_the_full_kernel(om_kind):
    mdp = chain()
    om, _ = chain_model(om_kind, np.full((3, 3), 1 / 3))
    obs = np.full((2, 4), -1)
    # two moves of probability e^-300 in a row predict e^-600 < e^-F for the last state
    log_pi = np.tile([np.log1p(-np.exp(-300.0)), -300.0], (3, 1))
    assert not both_kernels(mdp, log_pi, om, obs, np.array([4, 4]))[0]
    ok, ll, occ, init = both_kernels(mdp, log_pi, om, obs, np.array([2, 1]))
    assert ok
    assert_same(PosteriorStats(ll, occ, init),
                forward_backward(mdp, log_pi, obs[:, :2], om, lengths=np.array([2, 1]),
                                 method="log"), atol=1e-15)
    # an initial probability below the floor
    log_pi = np.log(np.full((3, 2), 0.5))
    p0 = np.array([1.0, 1e-200, 0.0])
    assert not both_kernels(mdp, log_pi, om, obs[:1, :2], np.array([2]), p0=p0)[0]


@pytest.mark.parametrize("om_kind", SEPARABLE_KINDS)
def test_separable_kernel_fails_on_impossible_observations(om_kind):
    mdp = chain()
    log_pi = np.log(np.full((3, 2), 0.5))
    # state 2 observed at step 1: possible under some pair, but the chain cannot reach it
    om, code = chain_model(om_kind, np.eye(3))
    obs = np.array([[-1, code(2)], [code(0), code(0)]])
    assert np.isfinite(om.separable_likelihoods(obs)[2]).all()
    assert not both_kernels(mdp, log_pi, om, obs, np.array([2, 2]))[0]
    assert both_kernels(mdp, log_pi, om, obs[1:], np.array([2]))[0]
    # state 2 observed where no state shows as 2: undefined parts (NaN), shift -inf
    om, code = chain_model(om_kind, np.array([[1.0, 0, 0], [0, 1, 0], [0, 1, 0]]))
    obs = np.array([[code(0), code(1), code(2)]])
    assert np.isneginf(om.separable_likelihoods(obs)[2][0, 2])
    assert not separable_kernel(mdp, log_pi, om, obs, np.array([3]))[0]
    assert both_kernels(mdp, log_pi, om, obs, np.array([2]))[0]  # the step after the end


def test_separable_kernel_checks_its_shapes():
    mdp = chain()
    ops = _numba.operator_arrays(mdp._action_major)
    pi, p0 = np.full((2, 3), 0.5), mdp.initial
    state, action, shift = np.ones((1, 2, 3)), np.ones((1, 2, 2)), np.zeros((1, 2))
    run = _numba.scaled_forward_backward_separable
    assert run(*ops, pi, state, action, shift, [2], p0, 300.0)[0]
    for bad_state, bad_action, bad_pi in ((state[:, :1], action, pi),
                                          (state, np.ones((1, 2, 3)), pi),
                                          (state, action, pi.T),
                                          (state[0], action[0], pi)):
        with pytest.raises(ValueError, match="state and action"):
            run(*ops, bad_pi, bad_state, bad_action, shift, [2], p0, 300.0)
    with pytest.raises(ValueError, match="shift"):
        run(*ops, pi, state, action, shift[:, :1], [2], p0, 300.0)
    with pytest.raises(ValueError, match="lengths"):
        run(*ops, pi, state, action, shift, [3], p0, 300.0)
    with pytest.raises(ValueError, match="CSR"):
        run(ops[0], ops[1] + 1, ops[2], pi, state, action, shift, [2], p0, 300.0)


def test_operator_arrays_drop_zeros_of_dense_and_sparse_operators():
    dense = np.array([[0.5, 0.5, 0.0], [0.0, 1.0, 0.0]])
    for op in (dense, sp.csr_matrix(dense), sp.csr_matrix((dense * 0.0) + dense)):
        indptr, indices, data = _numba.operator_arrays(op)
        np.testing.assert_array_equal(indptr, [0, 2, 3])
        np.testing.assert_array_equal(indices, [0, 1, 1])
        np.testing.assert_array_equal(data, [0.5, 0.5, 1.0])


def test_mismatched_shapes_are_errors():
    mdp = chain()
    ops = _numba.operator_arrays(mdp._action_major)
    pi, p0 = np.full((2, 3), 0.5), mdp.initial
    factor, shift = np.ones((1, 2, 2, 3)), np.zeros((1, 2))
    with pytest.raises(ValueError, match="factor"):
        _numba.scaled_forward_backward(*ops, pi.T, factor, shift, [2], p0, 300.0)
    with pytest.raises(ValueError, match="lengths"):
        _numba.scaled_forward_backward(*ops, pi, factor, shift, [3], p0, 300.0)
    with pytest.raises(ValueError, match="CSR"):
        _numba.scaled_forward_backward(ops[0][:-1], *ops[1:], pi, factor, shift, [2], p0,
                                       300.0)
    with pytest.raises(ValueError, match="CSR"):  # a column index out of range
        _numba.scaled_forward_backward(ops[0], ops[1] + 1, ops[2], pi, factor, shift, [2], p0,
                                       300.0)


def test_irl_does_not_need_numba():
    code = ("import sys; sys.modules['numba'] = None; import irl, irl.inference, irl._numba; "
            "assert not irl._numba.available()")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=Path(__file__).parents[2])


def test_a_fit_with_the_numba_backend_equals_the_numpy_fit():
    """MMAPBIRL(backend="numba") runs every batch through the kernel and finds the weights
    the default backend finds."""
    dom = irl.domains.onion_sorting(noise=0.3)
    demos, _ = dom.sample(12, 20, occlusion=0.2, seed=7)
    kw = {"beta": dom.beta, "prior": dom.prior, "seed": 0}
    ref = irl.MMAPBIRL(dom.mdp, dom.observation_model, **kw).fit(demos)
    fast = irl.MMAPBIRL(dom.mdp, dom.observation_model, backend="numba", **kw).fit(demos)
    np.testing.assert_allclose(fast.theta_, ref.theta_, rtol=1e-8, atol=1e-10)
    assert fast.log_posterior_ == pytest.approx(ref.log_posterior_, rel=1e-12)
    assert fast.n_iter_ == ref.n_iter_


# -- the Kronecker entry point ------------------------------------------------------------

def factored_model(rng, sizes=(2, 3, 2), n_actions=3):
    """A factored model of ``prod(sizes)`` states read through one noisy confusion per
    factor, and a noisy action sensor."""
    def noisy(n):
        return 0.6 * np.eye(n) + 0.4 * rng.dirichlet(np.ones(n), size=n)
    return FactoredObservationModel([noisy(n) for n in sizes], noisy(n_actions))


@pytest.mark.parametrize("sizes", [(12,), (3, 4), (2, 3, 2)])
def test_kronecker_parts_are_the_separable_state_part_bit_for_bit(sizes):
    rng = np.random.default_rng(sum(sizes))
    om = factored_model(rng, sizes)
    obs = np.array([random_demo(rng, 9, om.n_observations, 0.3).as_array() for _ in range(4)])
    head, tail, action, shift, min_log = om.kronecker_likelihoods(obs)
    state, action_s, shift_s, min_log_s = om.separable_likelihoods(obs)
    assert head.shape[:2] == tail.shape[:2] == obs.shape
    assert tail.shape[2] == sizes[-1]
    np.testing.assert_array_equal((head[..., :, None] * tail[..., None, :]).reshape(state.shape),
                                  state)
    np.testing.assert_array_equal(action, action_s)
    np.testing.assert_array_equal(shift, shift_s)
    assert min_log == min_log_s


@pytest.mark.parametrize("sizes", [(6,), (2, 3), (2, 3, 2)])
def test_kronecker_kernel_equals_the_separable_kernel_bit_for_bit(sizes):
    rng = np.random.default_rng(40 + len(sizes))
    S = int(np.prod(sizes))
    mdp = make_mdp(rng, "sparse", n_states=S)
    om = factored_model(rng, sizes)
    log_pi = np.log(rng.dirichlet(np.ones(mdp.n_actions), size=S))
    obs = np.array([random_demo(rng, 12, om.n_observations, 0.3).as_array() for _ in range(3)])
    lengths = np.array([12, 7, 12])
    obs[1, 7:] = -1
    head, tail, action, shift, _ = om.kronecker_likelihoods(obs)
    got = _numba.scaled_forward_backward_kronecker(
        *_numba.operator_arrays(mdp._action_major), np.exp(log_pi.T), head, tail, action,
        shift, lengths, np.exp(mdp.log_initial), _scaled_floor(mdp))
    want = separable_kernel(mdp, log_pi, om, obs, lengths)
    assert got[0] and want[0]
    for g, w in zip(got[1:], want[1:], strict=True):
        np.testing.assert_array_equal(g, w)
    with pytest.raises(ValueError, match="head, tail and action"):
        _numba.scaled_forward_backward_kronecker(
            *_numba.operator_arrays(mdp._action_major), np.exp(log_pi.T), head, tail[:, :, :1],
            action, shift, lengths, np.exp(mdp.log_initial), _scaled_floor(mdp))


def test_gradient_on_a_factored_grid_equals_the_numpy_backend():
    """The numba backend, which now takes a factored sensor's state parts as two factors,
    gives the numpy backend's MMAP-BIRL gradient to 1e-10 on the bench's grid."""
    mdp = irl.domains.grid_mdp(12, 9, seed=0)
    sensor = irl.factored_observation_model([0.8 * np.eye(12) + 0.2 / 12,
                                             0.8 * np.eye(9) + 0.2 / 9], n_actions=4)
    theta = np.array([1.0, -1.0, 0.5, -0.5])
    rng = np.random.default_rng(3)
    pi = np.exp(irl.solvers.log_boltzmann_policy(
        irl.solvers.OptimalQSolver(mdp).q_values(theta), 1.0))
    demos = [irl.demonstrations.observe(irl.demonstrations.sample_trajectory(
        mdp, pi, 30, rng), sensor, 0.2, rng) for _ in range(4)]
    grads = [irl.MMAPBIRL(mdp, sensor, beta=1.0, backend=b).log_posterior_gradient(
        theta * 0.8, demos) for b in ("numpy", "numba")]
    np.testing.assert_allclose(grads[1], grads[0], rtol=0, atol=1e-10)
