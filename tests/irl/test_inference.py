import numpy as np
import pytest

import irl
from irl.inference import forward_backward, posterior_stats
from tests.irl.conftest import (
    OM_KINDS,
    brute_force,
    random_demo,
    random_mdp,
    random_observation_model,
)


@pytest.mark.parametrize("kind", OM_KINDS)
@pytest.mark.parametrize("method", ["auto", "log"])
@pytest.mark.parametrize("sparse", [False, True])
@pytest.mark.parametrize("seed", range(6))
def test_forward_backward_equals_enumeration(seed, sparse, method, kind):
    rng = np.random.default_rng(seed)
    mdp = random_mdp(rng, sparse=sparse)
    om = random_observation_model(rng, mdp.n_states, mdp.n_actions, kind=kind)
    pi = rng.dirichlet(np.ones(mdp.n_actions), size=mdp.n_states)
    demos = [random_demo(rng, length, om.n_observations) for length in (1, 3, 4, 4)]
    stats = posterior_stats(mdp, np.log(pi), demos, om, method=method)
    for i, d in enumerate(demos):
        dense = random_mdp(np.random.default_rng(seed)) if sparse else mdp
        ll, marg = brute_force(dense, pi, om, d)
        assert stats.log_likelihood[i] == pytest.approx(ll, rel=1e-10, abs=1e-10)
        np.testing.assert_allclose(stats.occupancy[i], marg.sum(axis=0), atol=1e-10)
        np.testing.assert_allclose(stats.initial[i], marg[0].sum(axis=1), atol=1e-10)


@pytest.mark.parametrize("kind", OM_KINDS)
@pytest.mark.parametrize("method", ["auto", "log"])
def test_time_varying_policy_equals_enumeration(rng, method, kind):
    mdp = random_mdp(rng)
    om = random_observation_model(rng, mdp.n_states, mdp.n_actions, kind=kind)
    demo = random_demo(rng, 4, om.n_observations)
    pis = rng.dirichlet(np.ones(mdp.n_actions), size=(4, mdp.n_states))
    packed = demo.as_array()[None]
    stats = forward_backward(mdp, np.log(pis), packed, om, method=method)
    ll, marg = brute_force(mdp, pis, om, demo)
    assert stats.log_likelihood[0] == pytest.approx(ll, rel=1e-10)
    np.testing.assert_allclose(stats.occupancy[0], marg.sum(axis=0), atol=1e-10)


@pytest.mark.parametrize("kind", OM_KINDS)
def test_all_occluded_demo_has_likelihood_one(rng, kind):
    mdp = random_mdp(rng)
    om = random_observation_model(rng, mdp.n_states, mdp.n_actions, kind=kind)
    pi = rng.dirichlet(np.ones(mdp.n_actions), size=mdp.n_states)
    stats = posterior_stats(mdp, np.log(pi), [irl.Demonstration(observations=[None] * 5)], om)
    assert stats.log_likelihood[0] == pytest.approx(0.0, abs=1e-12)
    assert stats.occupancy[0].sum() == pytest.approx(5.0)


def test_ten_thousand_steps_equal_the_closed_form_likelihood():
    """A fully observed, noise-free demonstration has a closed-form likelihood,
    ``log p0(s_1) + sum_t log pi(a_t | s_t) + sum_t log T(s_t, a_t, s_{t+1})``: 10,000 steps of
    forward-backward (and of the log-space pass) must reproduce it, and the posterior must put
    each step on its observed pair."""
    dom = irl.domains.onion_sorting(noise=0.0)
    mdp, A = dom.mdp, dom.mdp.n_actions
    om = irl.identity_observation_model(mdp.n_states, A)
    _, (traj,) = dom.sample(1, 10_000, occlusion=0.0, seed=1)
    demo = irl.Demonstration.from_pairs(traj.states, traj.actions, A)
    log_pi = np.log(dom.expert_policy())
    s, a = traj.states, traj.actions
    T = mdp.transitions
    expected = (np.log(mdp.initial[s[0]]) + log_pi[s, a].sum()
                + np.log(T[s[:-1], a[:-1], s[1:]]).sum())
    assert expected < -1000  # e^expected underflows: only log space can hold it
    counts = np.zeros((mdp.n_states, A))
    np.add.at(counts, (s, a), 1.0)
    for method in ("auto", "log"):
        stats = posterior_stats(mdp, log_pi, [demo], om, method=method)
        assert stats.log_likelihood[0] == pytest.approx(expected, rel=1e-12)
        np.testing.assert_allclose(stats.occupancy[0], counts, atol=1e-8)


def test_ten_thousand_noisy_occluded_steps_agree_on_both_passes():
    dom = irl.domains.onion_sorting(noise=0.3)
    demos, _ = dom.sample(2, 10_000, occlusion=0.3, seed=1)
    log_pi = np.log(dom.expert_policy())
    fast = posterior_stats(dom.mdp, log_pi, demos, dom.observation_model)
    exact = posterior_stats(dom.mdp, log_pi, demos, dom.observation_model, method="log")
    np.testing.assert_allclose(fast.log_likelihood, exact.log_likelihood, rtol=1e-11)
    np.testing.assert_allclose(fast.occupancy, exact.occupancy, atol=1e-8)
    np.testing.assert_allclose(fast.occupancy.sum(axis=(1, 2)), 10_000, rtol=1e-9)


def _count_operator_calls(mdp, monkeypatch) -> dict[str, int]:
    """Count the transition-operator products forward-backward makes on ``mdp``."""
    calls = {"push_forward_columns": 0, "expect_next_columns": 0,
             "log_push_forward": 0, "log_expect_next": 0}

    def counting(name, kernel):
        def counted(*args, **kwargs):
            calls[name] += 1
            return kernel(*args, **kwargs)
        return counted

    for name in ("log_push_forward", "log_expect_next"):
        monkeypatch.setattr(mdp, name, counting(name, getattr(mdp, name)))
    products = mdp.column_products
    monkeypatch.setattr(mdp, "column_products", lambda n, weights=None: tuple(
        counting(name, kernel) for name, kernel in zip(
            ("push_forward_columns", "expect_next_columns"), products(n, weights),
            strict=True)))
    return calls


@pytest.mark.parametrize("occlusion", [0.0, 0.5, 1.0])
def test_cost_is_independent_of_occlusion(occlusion, monkeypatch):
    """The work is one push through T per step forward and one backward, whatever is occluded:
    occluded steps are marginalized, never enumerated, and never send the scaled pass to the
    slower log-space one."""
    dom = irl.domains.onion_sorting(noise=0.3)
    demos, _ = dom.sample(3, 200, occlusion=occlusion, seed=4)
    log_pi = np.log(dom.expert_policy())
    calls = _count_operator_calls(dom.mdp, monkeypatch)
    stats = posterior_stats(dom.mdp, log_pi, demos, dom.observation_model)
    assert calls == {"push_forward_columns": 199, "expect_next_columns": 199,
                     "log_push_forward": 0, "log_expect_next": 0}
    if occlusion == 1.0:
        assert stats.log_likelihood == pytest.approx(0.0, abs=1e-9)


def test_impossible_demonstration_names_demo_and_step():
    dom = irl.domains.forestworld(noise=0.0)
    pi = dom.expert_policy()
    A = dom.mdp.n_actions
    # A fugitive cannot jump from (0, 0) to (3, 3) in one move.
    ok = irl.Demonstration.from_pairs([0, 1], [0, 0], A)
    jump = irl.Demonstration.from_pairs([0, 15], [0, 0], A)
    with pytest.raises(ValueError, match=r"demos\[1\], step 1: observation \d+ is impossible"):
        posterior_stats(dom.mdp, np.log(pi), [ok, jump], dom.observation_model)


def _mdp_of(T, sparse: bool) -> irl.TabularMDP:
    """An MDP of transitions ``T[s, a, s']`` (rows renormalized), dense or one sparse matrix per
    action, with no reward to speak of."""
    import scipy.sparse as sps

    T = T / T.sum(axis=2, keepdims=True)
    S, A, _ = T.shape
    transitions = [sps.csr_matrix(T[:, a, :]) for a in range(A)] if sparse else T
    return irl.TabularMDP(transitions=transitions, features=np.zeros((S, A, 1)), discount=0.5,
                          initial=np.full(S, 1.0 / S))


@pytest.mark.parametrize("sparse", [False, True])
def test_log_space_kernels_equal_the_linear_ones(sparse, rng):
    """log_push_forward / log_expect_next are the logs of push_forward / expect_next, with -inf
    for zero mass and for a state nothing leads to (an empty column of T)."""
    T = rng.dirichlet(np.ones(4), size=(4, 3))
    T[:, :, 3] = 0.0  # state 3 is never entered
    T[1, 2, 1:] = 0.0  # a row with one successor
    mdp = _mdp_of(T, sparse)
    mass = rng.random((2, 4, 3))
    mass[0, 2] = 0.0
    values = rng.random((2, 4))
    values[1, 0] = 0.0
    with np.errstate(divide="ignore"):
        log_mass, log_values = np.log(mass), np.log(values)
        pushed = np.log(mdp.push_forward(mass))
        expected = np.log(np.moveaxis(mdp.expect_next(values.T), 2, 0))
    np.testing.assert_allclose(mdp.log_push_forward(log_mass), pushed, rtol=1e-13)
    np.testing.assert_allclose(mdp.log_expect_next(log_values), expected, rtol=1e-13)
    assert np.all(mdp.log_push_forward(log_mass)[:, 3] == -np.inf)
    # shifting every input by c shifts every output by c: nothing under- or overflows
    np.testing.assert_allclose(mdp.log_push_forward(log_mass - 5000.0),
                               mdp.log_push_forward(log_mass) - 5000.0, rtol=1e-13)


@pytest.mark.parametrize("kind", OM_KINDS)
@pytest.mark.parametrize("sparse", [False, True])
def test_step_by_step_chunks_equal_the_whole_batch(kind, sparse, rng, monkeypatch):
    """Observations computed one step at a time (what a batch too large to keep gets), with a
    state-times-action model's factors never formed, give the kept whole-batch pass and the
    log-space pass to 1e-12, ragged and time-indexed batches included."""
    mdp = random_mdp(rng, 6, 3, sparse=sparse)
    om = random_observation_model(rng, 6, 3, n_obs=5, kind=kind)
    pi = rng.dirichlet(np.ones(3), size=6)
    demos = [random_demo(rng, n, om.n_observations) for n in (7, 6, 7, 5)]
    kept = posterior_stats(mdp, np.log(pi), demos, om)
    exact = posterior_stats(mdp, np.log(pi), demos, om, method="log")
    pis = rng.dirichlet(np.ones(3), size=(7, 6))
    obs = np.array([d.as_array() for d in demos if len(d) == 7])
    timed = forward_backward(mdp, np.log(pis), obs, om)
    separable = []
    original = om.separable_likelihoods

    def counted(o):
        parts = original(o)
        separable.append(parts is not None)
        return parts

    monkeypatch.setattr(om, "separable_likelihoods", counted)
    monkeypatch.setattr(irl.inference.scaled, "_CHUNK_ELEMENTS", 1)
    blocked = []
    products = mdp.state_block_products
    monkeypatch.setattr(mdp, "state_block_products", lambda *args: blocked.append(
        products(*args)) or blocked[-1])
    # separable parts held for both passes, or computed in each; a sparse MDP's blocked pass
    # by blocks of 1, 2, 5 (then a short one of 1) and all 6 states (A = 3, one batch of 4)
    for held, block in ((1 << 24, 1), (0, 2 * 3 * 4), (1 << 24, 5 * 3 * 4), (0, 1 << 17)):
        monkeypatch.setattr(irl.inference.scaled, "_SEPARABLE_ELEMENTS", held)
        monkeypatch.setattr(irl.inference.blocked, "_BLOCK_ELEMENTS", block)
        chunked = posterior_stats(mdp, np.log(pi), demos, om)
        chunked_timed = forward_backward(mdp, np.log(pis), obs, om)
        assert any(separable) == (kind in ("factored", "state"))
        for a in (kept, exact):
            np.testing.assert_allclose(chunked.log_likelihood, a.log_likelihood, rtol=1e-12)
            np.testing.assert_allclose(chunked.occupancy, a.occupancy, rtol=1e-12, atol=1e-14)
            np.testing.assert_allclose(chunked.initial, a.initial, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(chunked_timed.log_likelihood, timed.log_likelihood,
                                   rtol=1e-12)
        np.testing.assert_allclose(chunked_timed.occupancy, timed.occupancy, rtol=1e-12,
                                   atol=1e-14)
    # the stationary policy's separable batches went by blocks where T is sparse
    assert any(b is not None for b in blocked) == (sparse and kind in ("factored", "state"))


@pytest.mark.parametrize("sparse", [False, True])
def test_column_kernels_equal_the_batch_ones(sparse, rng):
    """The products forward-backward makes on blocks held demonstrations-innermost equal
    push_forward and expect_next_batch, whether T is dense, sparse, or dense and mostly zero
    (multiplied through a CSR copy)."""
    T = rng.dirichlet(np.ones(5), size=(5, 3))
    T[T < 0.15] = 0.0
    mdp = _mdp_of(T, sparse)
    mass = rng.random((4, 5, 3))  # [n, s, a]
    values = rng.random((4, 5))  # [n, s']
    columns = np.ascontiguousarray(mass.transpose(2, 1, 0))  # [a, s, n]
    pushed = mdp.push_forward_columns(columns, out=np.empty((5, 4)))
    np.testing.assert_allclose(pushed.T, mdp.push_forward(mass), rtol=1e-14)
    expected = mdp.expect_next_batch(values)  # [n, s, a]
    got = mdp.expect_next_columns(np.ascontiguousarray(values.T), out=np.empty((3, 5, 4)))
    np.testing.assert_allclose(got.transpose(2, 1, 0), expected, rtol=1e-14)
    for w in (None, rng.random(15)):  # w: a policy folded into T (pair rows a * S + s)
        push, expect = mdp.column_products(4, w)  # the loop's bound form: out += product
        scaled = columns if w is None else columns * w.reshape(3, 5, 1)
        out = np.ones(20)
        push(columns.ravel(), out)
        np.testing.assert_allclose(out.reshape(5, 4), 1.0 + pushed_of(mdp, scaled), rtol=1e-14)
        out = np.ones(60)
        expect(np.ascontiguousarray(values.T).ravel(), out)
        expected = got if w is None else got * w.reshape(3, 5, 1)
        np.testing.assert_allclose(out.reshape(3, 5, 4), 1.0 + expected, rtol=1e-14)


@pytest.mark.parametrize("block", [1, 2, 5])
def test_state_block_products_equal_the_column_ones(block, rng):
    """The products by blocks of states (pairs action-major within each block, the policy
    folded in with weights indexed s * A + a) add what the column products compute."""
    T = rng.dirichlet(np.ones(5), size=(5, 3))
    T[T < 0.15] = 0.0
    mdp = _mdp_of(T, sparse=True)
    w = rng.random(15)  # [s * A + a]
    values = rng.random((5, 4))  # [s', n]
    push, expect = mdp.state_block_products(block, 4, w)
    pushed = np.ones((5, 3, 4))  # [s', a, n]: the mass through each action
    expected = np.ones((3, 5, 4))  # [a, s, n]
    for k, s0 in enumerate(range(0, 5, block)):
        m = min(block, 5 - s0)
        out = np.ones(3 * m * 4)
        push(k, values.ravel(), out)
        pushed[s0:s0 + m] = out.reshape(3, m, 4).transpose(1, 0, 2)
        out = np.ones(3 * m * 4)
        expect(k, values.ravel(), out)
        expected[:, s0:s0 + m] = out.reshape(3, m, 4)
    w_as = w.reshape(5, 3).T[:, :, None]  # [a, s, 1]
    for a in range(3):  # one action's mass at a time: what it sends through T
        only = np.zeros((3, 5, 4))
        only[a] = values * w_as[a]
        np.testing.assert_allclose(pushed[:, a], 1.0 + pushed_of(mdp, only), rtol=1e-14)
    got = mdp.expect_next_columns(values, out=np.empty((3, 5, 4)))
    np.testing.assert_allclose(expected, 1.0 + got * w_as, rtol=1e-14)
    assert _mdp_of(np.full((5, 3, 5), 0.2), sparse=False).state_block_products(
        block, 4, w) is None  # a dense MDP's products stay dense


def pushed_of(mdp, columns):
    return mdp.push_forward_columns(np.ascontiguousarray(columns), out=np.empty((5, 4)))


def test_folded_policy_is_exact_when_rows_sum_to_one_only_to_rounding(rng, monkeypatch):
    """The chunked pass with the policy folded into T normalizes each step by the pushed mass,
    which equals alpha's sum only as far as T's rows sum to 1; rows off by 1e-7 (accepted by
    the MDP's check) still give the log-space pass to 1e-12, ragged batches included."""
    T = rng.dirichlet(np.ones(6), size=(6, 3))
    T *= 1.0 + rng.uniform(-1e-7, 1e-7, size=(6, 3, 1))
    mdp = irl.TabularMDP(transitions=T, features=rng.normal(size=(6, 3, 2)), discount=0.9,
                         initial=rng.dirichlet(np.ones(6)))
    om = random_observation_model(rng, 6, 3, kind="factored")
    pi = rng.dirichlet(np.ones(3), size=6)
    demos = [random_demo(rng, n, om.n_observations) for n in (9, 4, 9, 6)]
    exact = posterior_stats(mdp, np.log(pi), demos, om, method="log")
    monkeypatch.setattr(irl.inference.scaled, "_CHUNK_ELEMENTS", 1)
    folded = posterior_stats(mdp, np.log(pi), demos, om)
    np.testing.assert_allclose(folded.log_likelihood, exact.log_likelihood, rtol=1e-12)
    np.testing.assert_allclose(folded.occupancy, exact.occupancy, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(folded.initial, exact.initial, rtol=1e-12, atol=1e-14)


def test_large_scratch_is_held_only_inside_scratch_held(monkeypatch):
    """A pass drops its large scratch arrays when it ends; inside ``scratch_held`` the next
    pass reuses them, and they are dropped when the block exits."""
    dom = irl.domains.onion_sorting(noise=0.3)
    demos, _ = dom.sample(3, 20, seed=0)
    log_pi = np.log(dom.expert_policy())
    monkeypatch.setattr(irl.inference.workspace, "_WORKSPACE_ELEMENTS", 0)  # every array is "large"
    ws = irl.inference.workspace._workspace
    posterior_stats(dom.mdp, log_pi, demos, dom.observation_model)
    assert ws.arrays == {}
    with irl.inference.scratch_held():
        posterior_stats(dom.mdp, log_pi, demos, dom.observation_model)
        held = dict(ws.arrays)
        assert "preds" in held
        again = posterior_stats(dom.mdp, log_pi, demos, dom.observation_model)
        assert all(ws.arrays[k] is a for k, a in held.items())
    assert ws.arrays == {}
    alone = posterior_stats(dom.mdp, log_pi, demos, dom.observation_model)
    np.testing.assert_array_equal(again.occupancy, alone.occupancy)


def test_backend_is_checked_by_name(monkeypatch):
    dom = irl.domains.onion_sorting(noise=0.3)
    demos, _ = dom.sample(2, 5, seed=0)
    log_pi = np.log(dom.expert_policy())
    with pytest.raises(ValueError, match=r"backend must be one of \('numpy', 'numba'\); got 'gpu'"):
        posterior_stats(dom.mdp, log_pi, demos, dom.observation_model, backend="gpu")
    with pytest.raises(TypeError, match="backend must be one of"):
        irl.MMAPBIRL(dom.mdp, dom.observation_model, backend=None).fit(demos)
    from irl import _numba

    monkeypatch.setattr(_numba, "available", lambda: False)
    with pytest.raises(ValueError, match=r"needs numba, which is not installed: pip install"):
        irl.MMAPBIRL(dom.mdp, dom.observation_model, backend="numba").fit(demos)


def test_a_lazily_renormalized_pass_out_of_range_is_run_again_at_every_step(monkeypatch):
    """Renormalizing every few steps can leave the scaled pass's range where renormalizing at
    every step does not: then the pass runs again, renormalizing at every step, before the
    log-space pass is considered."""
    dom = irl.domains.onion_sorting(noise=0.3)
    demos, _ = dom.sample(4, 30, occlusion=0.2, seed=3)
    log_pi = np.log(dom.expert_policy())
    exact = posterior_stats(dom.mdp, log_pi, demos, dom.observation_model, method="log")
    real, seen = irl.inference.api._scaled_forward_backward, []

    def lazy_out_of_range(*args, lazy=True):
        seen.append(lazy)
        return irl.inference.scaled._RENORMALIZE if lazy else real(*args, lazy=lazy)

    monkeypatch.setattr(irl.inference.api, "_scaled_forward_backward", lazy_out_of_range)
    again = posterior_stats(dom.mdp, log_pi, demos, dom.observation_model)
    assert seen == [True, False]
    np.testing.assert_allclose(again.log_likelihood, exact.log_likelihood, rtol=1e-12)
    np.testing.assert_allclose(again.occupancy, exact.occupancy, rtol=1e-12, atol=1e-14)
    # the pass says so itself only when it renormalized lazily; a batch too large for that
    # renormalizes at every step from the start
    monkeypatch.setattr(irl.inference.api, "_scaled_forward_backward", real)
    monkeypatch.setattr(irl.inference.api, "_LAZY_ELEMENTS", 0)
    calls = []
    monkeypatch.setattr(irl.inference.api, "_scaled_forward_backward",
                        lambda *a, lazy=True: calls.append(lazy) or real(*a, lazy=lazy))
    posterior_stats(dom.mdp, log_pi, demos, dom.observation_model)
    assert calls == [False]
