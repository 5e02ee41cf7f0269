"""irl._blas: one BLAS thread inside irl's large passes, none of its cost below the size."""

import threading

import numpy as np
import pytest
from threadpoolctl import ThreadpoolController, threadpool_limits

import irl
from irl import _blas
from irl.inference import posterior_stats
from irl.solvers import OptimalQSolver, log_boltzmann_policy


def _blas_threads() -> list[int]:
    return [lib["num_threads"] for lib in ThreadpoolController().select(user_api="blas").info()]


@pytest.fixture
def two_threads():
    """BLAS on two threads outside the block under test (as on a 2-core machine)."""
    with threadpool_limits(2, user_api="blas"):
        if max(_blas_threads(), default=1) < 2:
            pytest.skip("this BLAS cannot run two threads")
        yield


def test_one_thread_inside_a_large_block_and_restored_after(two_threads):
    with _blas.one_blas_thread(_blas.MIN_ELEMENTS):
        assert _blas_threads() and set(_blas_threads()) == {1}
        with _blas.one_blas_thread(10 * _blas.MIN_ELEMENTS):  # nested: left as it is
            assert set(_blas_threads()) == {1}
        assert set(_blas_threads()) == {1}
    assert max(_blas_threads()) == 2


def test_a_small_block_leaves_blas_alone(two_threads):
    with _blas.one_blas_thread(_blas.MIN_ELEMENTS - 1):
        assert max(_blas_threads()) == 2


def test_the_nesting_flag_is_per_thread(two_threads):
    seen = []
    with _blas.one_blas_thread(_blas.MIN_ELEMENTS):
        other = threading.Thread(target=lambda: seen.append(_blas._inside.__dict__.get("active")))
        other.start()
        other.join()
        assert _blas._inside.active
    assert seen == [None] and not _blas._inside.active


def test_the_gradient_on_one_thread_equals_the_default_pool(two_threads, monkeypatch):
    """The limit changes how the products are summed, not what they are (to 1e-10)."""
    mdp = irl.domains.grid_mdp(60, 60, seed=1)  # S A = 14,400: over the threshold
    theta = np.array([1.0, -1.0, 0.5, -0.5])
    pi = np.exp(log_boltzmann_policy(OptimalQSolver(mdp).q_values(theta), 1.0))
    rng = np.random.default_rng(0)
    om = irl.state_observation_model(np.eye(mdp.n_states) * 0.8 + 0.2 / mdp.n_states,
                                     n_actions=mdp.n_actions)
    demos = [irl.demonstrations.observe(irl.demonstrations.sample_trajectory(mdp, pi, 30, rng),
                                        om, 0.2, rng) for _ in range(3)]
    est = irl.MMAPBIRL(mdp, om, beta=1.0)
    limited = est.log_posterior_gradient(theta * 0.9, demos)
    monkeypatch.setattr(_blas, "MIN_ELEMENTS", 10**12)  # the pool, as before the change
    pooled = irl.MMAPBIRL(mdp, om, beta=1.0).log_posterior_gradient(theta * 0.9, demos)
    np.testing.assert_allclose(limited, pooled, rtol=1e-10, atol=1e-10)
    log_pi = log_boltzmann_policy(OptimalQSolver(mdp).q_values(theta), 1.0)
    assert np.isfinite(posterior_stats(mdp, log_pi, demos, om).log_likelihood).all()


def test_the_pool_is_restored_when_the_block_raises(two_threads):
    with pytest.raises(RuntimeError, match="inside"), _blas.one_blas_thread(_blas.MIN_ELEMENTS):
        raise RuntimeError("inside")
    assert max(_blas_threads()) == 2 and not _blas._inside.active
    with _blas.one_blas_thread(_blas.MIN_ELEMENTS):  # and the next block limits again
        assert set(_blas_threads()) == {1}


def test_blocks_of_two_threads_that_overlap_give_the_pool_back(two_threads):
    """The limit is the process's: where the main thread's block and a worker's overlap and
    the worker's leaves last, BLAS stays on one thread until then and gets its pool back
    after (it stayed on one thread for good)."""
    worker_in, main_out, seen = threading.Event(), threading.Event(), []

    def worker():
        with _blas.one_blas_thread(_blas.MIN_ELEMENTS):
            worker_in.set()
            main_out.wait(20)
            seen.append(max(_blas_threads()))

    thread = threading.Thread(target=worker)
    with _blas.one_blas_thread(_blas.MIN_ELEMENTS):
        thread.start()
        worker_in.wait(20)
    main_out.set()
    thread.join(20)
    assert seen == [1]  # inside the worker's block after the main thread's left
    assert max(_blas_threads()) == 2
