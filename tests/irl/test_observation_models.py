"""The observation-model implementations agree with the dense array they stand for, and the
learners and forward-backward cannot tell them apart (exactness: tests/irl/test_inference.py
and test_numerics.py run for every implementation)."""

import tracemalloc
from functools import reduce

import numpy as np
import pytest
import scipy.sparse as sp

import irl
from irl.inference import pack_demonstrations, posterior_stats
from irl.inference.packing import _padded_batches
from irl.observation import (
    DenseObservationModel,
    FactoredObservationModel,
    SparseObservationModel,
    StateObservationModel,
)
from tests.irl.conftest import OM_KINDS, random_demo, random_mdp, random_observation_model


def as_dense(om) -> DenseObservationModel:
    """The dense model of the same ``O[s, a, o]`` and nominal pairs."""
    return irl.ObservationModel(om.probs, nominal=om.nominal)


def factored_mdp(rng, sizes=(2, 3), n_actions=2, n_features=3):
    S = int(np.prod(sizes))
    mdp = random_mdp(rng, S, n_actions, n_features)
    om = FactoredObservationModel(
        [rng.dirichlet(np.ones(n), size=n) for n in sizes],
        rng.dirichlet(np.ones(n_actions), size=n_actions),
    )
    return mdp, om


def test_observation_model_of_an_array_is_the_dense_implementation():
    om = irl.ObservationModel(np.full((2, 3, 4), 0.25))
    assert type(om) is DenseObservationModel
    assert isinstance(om, irl.ObservationModel)
    with pytest.raises(TypeError, match="abstract"):
        type("Incomplete", (irl.ObservationModel,), {})()


@pytest.mark.parametrize("kind", OM_KINDS)
def test_every_implementation_equals_its_dense_array(kind, rng):
    om = random_observation_model(rng, 4, 3, n_obs=5, kind=kind)
    dense = as_dense(om)
    obs = np.array([[0, -1, om.n_observations - 1], [-1, -1, 2]])
    np.testing.assert_allclose(om.log_likelihoods(obs), dense.log_likelihoods(obs), rtol=1e-13,
                               atol=0)
    assert om.log_likelihoods(obs).shape == (2, 3, 4, 3)
    assert np.all(om.log_likelihoods(obs)[:, 1] == 0.0)  # occluded: a factor of 1
    for o in range(om.n_observations):
        np.testing.assert_allclose(om.likelihood(o), dense.probs[:, :, o], rtol=1e-13, atol=0)
    np.testing.assert_array_equal(np.isneginf(om.log_emissions[:-1]),
                                  np.moveaxis(dense.probs, 2, 0) == 0.0)
    for s in range(om.n_states):
        for a in range(om.n_actions):
            np.testing.assert_allclose(om.distribution(s, a), dense.probs[s, a], rtol=1e-15)
    np.testing.assert_allclose(om.probs.sum(axis=2), 1.0, rtol=1e-12)


def test_factored_model_is_the_kronecker_product_of_its_factors(rng):
    mats = [rng.dirichlet(np.ones(n), size=n) for n in (2, 3, 2)]
    C_A = rng.dirichlet(np.ones(3), size=3)
    om = irl.factored_observation_model(mats, C_A)
    C_S = reduce(np.kron, mats)
    S, A = 12, 3
    expected = np.einsum("st,ab->satb", C_S, C_A).reshape(S, A, S * A)
    np.testing.assert_allclose(om.probs, expected, rtol=1e-14)
    np.testing.assert_allclose(np.exp(om.log_likelihoods(np.arange(S * A))),
                               np.moveaxis(expected, 2, 0), rtol=1e-13)
    np.testing.assert_array_equal(om.nominal, np.stack(np.divmod(np.arange(S * A), A), axis=1))
    assert om.error_rate() == pytest.approx(as_dense(om).error_rate(), rel=1e-13)


@pytest.mark.parametrize("seed", range(4))
def test_factored_and_dense_give_equal_likelihoods_and_gradients(seed):
    rng = np.random.default_rng(seed)
    mdp, om = factored_mdp(rng)
    dense = as_dense(om)
    demos = [random_demo(rng, n, om.n_observations) for n in (3, 5, 5, 8)]
    theta = rng.normal(size=mdp.n_features)
    for cls in (irl.MMAPBIRL, irl.MAPBIRL):
        f, d = cls(mdp, om), cls(mdp, dense)
        assert f.log_likelihood(theta, demos) == pytest.approx(d.log_likelihood(theta, demos),
                                                               rel=1e-12)
        np.testing.assert_allclose(f.log_posterior_gradient(theta, demos),
                                   d.log_posterior_gradient(theta, demos), rtol=1e-12,
                                   atol=1e-12)
    ef = irl.HiddenDataEM(mdp, om).e_step(theta, demos)
    ed = irl.HiddenDataEM(mdp, dense).e_step(theta, demos)
    np.testing.assert_allclose(ef.log_likelihood, ed.log_likelihood, rtol=1e-12)
    np.testing.assert_allclose(ef.occupancy, ed.occupancy, rtol=1e-12, atol=1e-13)


def test_sorting_fits_equal_with_factored_and_dense_models():
    dom = irl.domains.onion_sorting(noise=0.3)
    assert isinstance(dom.observation_model, FactoredObservationModel)
    demos, _ = dom.sample(6, 12, occlusion=0.3, seed=3)
    kw = {"beta": dom.beta, "prior": dom.prior, "seed": 0}
    f = irl.MMAPBIRL(dom.mdp, dom.observation_model, **kw).fit(demos)
    d = irl.MMAPBIRL(dom.mdp, as_dense(dom.observation_model), **kw).fit(demos)
    np.testing.assert_allclose(f.theta_, d.theta_, rtol=1e-8, atol=1e-10)
    assert f.log_posterior_ == pytest.approx(d.log_posterior_, rel=1e-12)


def test_factored_and_dense_models_draw_the_same_observations():
    dom = irl.domains.onion_sorting(noise=0.3)
    a, _ = dom.sample(3, 30, occlusion=0.2, seed=7)
    b, _ = dom.sample(3, 30, occlusion=0.2, seed=7, observation_model=as_dense(
        dom.observation_model))
    assert a == b


def test_a_factored_model_at_100000_states_never_forms_its_array():
    """O[s, a, o] would be 100,000 x 4 x 400,000 floats (1.3 TB); one observation's
    likelihoods over every pair are 400,000 floats."""
    confusion = [np.full((n, n), 0.1 / (n - 1)) + np.eye(n) * (0.9 - 0.1 / (n - 1))
                 for n in (100, 1000)]
    tracemalloc.start()
    om = irl.factored_observation_model(confusion, n_actions=4)
    ll = om.log_likelihoods(np.array([[5, -1, 399_999]]))
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert om.n_states == 100_000 and om.n_observations == 400_000
    assert ll.shape == (1, 3, 100_000, 4)
    assert peak < 64 * 2**20
    s, a = divmod(5, 4)  # observation 5 reports the pair (1, 1)
    assert ll[0, 0, s, a] == pytest.approx(np.log(0.9) * 2)
    assert ll[0, 0, s, 0] == -np.inf  # actions are observed exactly


def test_sparse_model_keeps_structural_zeros_impossible(rng):
    M = np.array([[1.0, 0.0], [0.5, 0.5], [0.0, 1.0], [0.2, 0.8]])
    om = SparseObservationModel(sp.csr_matrix(M), n_actions=2)
    ll = om.log_likelihoods(np.array([0, 1]))
    assert ll[0, 1, 0] == -np.inf and ll[1, 0, 0] == -np.inf
    np.testing.assert_allclose(np.exp(ll[1]), M[:, 1].reshape(2, 2))
    np.testing.assert_array_equal(om.nominal, [[0, 0], [1, 0]])


def test_state_model_repeats_the_state_likelihood_over_actions(rng):
    C = rng.dirichlet(np.ones(3), size=3)
    for om in (StateObservationModel(C, 4), irl.state_observation_model(sp.csr_matrix(C), 4)):
        np.testing.assert_allclose(np.exp(om.log_likelihood(1)), np.repeat(C[:, 1:2], 4, 1),
                                   rtol=1e-14)
        np.testing.assert_array_equal(om.nominal, [[0, -1], [1, -1], [2, -1]])


@pytest.mark.parametrize("build, match", [
    (lambda: FactoredObservationModel(np.eye(2), n_actions=2), "factor_confusions"),
    (lambda: FactoredObservationModel([], n_actions=2), "factor_confusions"),
    (lambda: FactoredObservationModel([np.ones((2, 3)) / 3], n_actions=2),
     r"factor_confusions\[0\]"),
    (lambda: FactoredObservationModel([np.eye(2)]), "action_confusion or n_actions"),
    (lambda: FactoredObservationModel([np.eye(2)], np.eye(3), n_actions=2), "n_actions"),
    (lambda: FactoredObservationModel([np.eye(2) * 2], n_actions=2), r"factor_confusions\[0\]"),
    (lambda: SparseObservationModel("M", 2), "matrix"),
    (lambda: SparseObservationModel(sp.csr_matrix(np.eye(3)), 2), "matrix"),
    (lambda: SparseObservationModel(sp.csr_matrix(np.eye(4) * 2), 2), "matrix"),
    (lambda: SparseObservationModel(np.eye(4), 0), "n_actions"),
    (lambda: SparseObservationModel(np.eye(4), 2, nominal=[[9, 0]] * 4), "nominal"),
    (lambda: StateObservationModel(None, 2), "state_confusion"),
    (lambda: StateObservationModel(np.ones(3), 2), "state_confusion"),
    (lambda: StateObservationModel(sp.csr_matrix(-np.eye(2)), 2), "state_confusion"),
    (lambda: StateObservationModel(np.eye(2), 2, observation_names=["a"]),
     "observation_names"),
])
def test_bad_arguments_are_one_line_errors_naming_the_argument(build, match):
    with pytest.raises((TypeError, ValueError), match=match) as info:
        build()
    assert "\n" not in str(info.value)


# -- batching -------------------------------------------------------------------------------

def test_padded_batches_bound_the_padding():
    assert [b.tolist() for b in _padded_batches(np.array([20, 20, 19, 20]), 0.25)] == [
        [0, 1, 2, 3]]
    lengths = np.array([1000, 3, 2, 4, 990, 4])
    batches = _padded_batches(lengths, 0.25)
    assert sorted(sorted(b.tolist()) for b in batches) == [[0, 4], [1, 2, 3, 5]]
    for b in batches:
        assert len(b) * lengths[b].max() <= 1.25 * lengths[b].sum()


@pytest.mark.parametrize("kind", OM_KINDS)
@pytest.mark.parametrize("method", ["auto", "log"])
def test_ragged_padded_batch_equals_one_pass_per_demonstration(kind, method, rng):
    mdp = random_mdp(rng, 4, 3, sparse=True)
    om = random_observation_model(rng, 4, 3, n_obs=5, kind=kind)
    pi = rng.dirichlet(np.ones(3), size=4)
    demos = [random_demo(rng, n, om.n_observations) for n in (7, 6, 1, 7, 5)]
    packed = pack_demonstrations(demos, om)
    assert len(packed.batches) < len(demos)  # some share a padded batch
    together = posterior_stats(mdp, np.log(pi), packed, method=method)
    for i, d in enumerate(demos):
        alone = posterior_stats(mdp, np.log(pi), [d], om, method=method)
        assert together.log_likelihood[i] == pytest.approx(alone.log_likelihood[0], rel=1e-12)
        np.testing.assert_allclose(together.occupancy[i], alone.occupancy[0], rtol=1e-12,
                                   atol=1e-14)
        np.testing.assert_allclose(together.initial[i], alone.initial[0], rtol=1e-12,
                                   atol=1e-14)
        np.testing.assert_allclose(together.occupancy[i].sum(), len(d), rtol=1e-12)


def test_packing_once_gives_the_same_statistics_as_packing_per_call(rng):
    dom = irl.domains.onion_sorting(noise=0.3)
    demos, _ = dom.sample(5, 9, occlusion=0.4, seed=2)
    log_pi = np.log(dom.expert_policy())
    packed = pack_demonstrations(demos, dom.observation_model)
    assert all(f is not None for f in packed.factors)  # small: kept for every pass
    uncached = pack_demonstrations(demos, dom.observation_model, cache=False)
    a = posterior_stats(dom.mdp, log_pi, packed)
    b = posterior_stats(dom.mdp, log_pi, uncached)
    np.testing.assert_array_equal(a.log_likelihood, b.log_likelihood)
    np.testing.assert_array_equal(a.occupancy, b.occupancy)


def test_time_indexed_policies_need_an_equal_length_packing(rng):
    dom = irl.domains.forestworld(noise=0.3)
    demos, _ = dom.sample(3, 6, occlusion=0.2, seed=0)
    packed = pack_demonstrations(demos + dom.sample(1, 4, seed=1)[0], dom.observation_model)
    with pytest.raises(ValueError, match="equal_lengths=True"):
        posterior_stats(dom.mdp, None, packed, log_policies_by_length=lambda T: None)
