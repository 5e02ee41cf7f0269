"""The forward-backward backend of a sweep: it reaches the learners that run forward-backward
(and only those), is recorded in each result, is refused when it cannot run, and changes no
result beyond rounding."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import irl
import irl._numba
import irl.experiments
import irl.inference
from irl.experiments import METHODS, SweepConfig, Trial, run_sweep, run_trial, sample_batch
from irl.learners import LearnerSpec, make_estimator, register_learner, unregister_learner

#: The learners that run forward-backward, and so take a backend.
TAKES_BACKEND = {"mmap-birl": True, "map-birl": False, "hidden-data-em": False, "maxent": False,
                 "bc": True, "bc-em": True}
NUMBA_MISSING = r"backend 'numba' needs numba, which is not installed: pip install"


@pytest.fixture
def numba_missing(monkeypatch):
    """``irl.inference.check_backend`` sees no numba."""
    monkeypatch.setattr(irl._numba, "available", lambda: False)


@pytest.fixture
def numba_present(monkeypatch):
    """``check_backend`` accepts numba whether or not it is installed (for tests that build
    learners without fitting them)."""
    monkeypatch.setattr(irl._numba, "available", lambda: True)


# -- make_estimator ------------------------------------------------------------------------


@pytest.mark.parametrize("method", METHODS)
def test_make_estimator_gives_the_backend_to_the_learners_that_take_one(method, numba_present):
    dom = irl.domains.onion_sorting(noise=0.3)
    est = make_estimator(method, dom, seed=0, backend="numba")
    assert ("backend" in est.get_params()) == TAKES_BACKEND[method]
    if TAKES_BACKEND[method]:
        assert est.backend == "numba"
        assert make_estimator(method, dom).backend == "numpy"  # None: the learner's default
    else:
        assert not hasattr(est, "backend")


def test_make_estimator_builds_a_learner_without_get_params_as_it_is():
    class Plain:
        def fit(self, demos):
            return self

    spec = register_learner(LearnerSpec("plain-test", "No parameters at all.",
                                        lambda domain, *, seed=None: Plain()))
    try:
        est = make_estimator("plain-test", irl.domains.forestworld(), backend="numpy")
    finally:
        assert unregister_learner("plain-test") is spec
    assert type(est) is Plain and not hasattr(est, "backend")


@pytest.mark.parametrize("method", ["mmap-birl", "maxent"])
def test_make_estimator_refuses_a_backend_that_cannot_run(method, numba_missing):
    dom = irl.domains.forestworld()
    with pytest.raises(ValueError, match=r"backend must be one of \('numpy', 'numba'\); "
                                         r"got 'cuda'"):
        make_estimator(method, dom, backend="cuda")
    with pytest.raises(ValueError, match=NUMBA_MISSING):
        make_estimator(method, dom, backend="numba")
    assert make_estimator(method, dom, backend="numpy") is not None


# -- sweeps --------------------------------------------------------------------------------


def test_trials_carry_the_sweeps_backend_but_not_in_their_data(numba_present):
    cfg = SweepConfig("sorting", ((0.2, 0.3),), batches=2, trajectories=2, length=4,
                      backend="numba")
    trials = cfg.trials()
    assert {t.backend for t in trials} == {"numba"}
    dom = irl.domains.onion_sorting(noise=0.3)
    for trial in trials[:2]:
        numpy_trial = dataclasses.replace(trial, backend="numpy")
        assert ([d.observations for d in sample_batch(dom, trial)]
                == [d.observations for d in sample_batch(dom, numpy_trial)])


@pytest.mark.parametrize("method", METHODS)
def test_run_trial_fits_with_the_trials_backend(method, built, monkeypatch):
    pytest.importorskip("numba")
    seen = []
    real = irl.inference.api.forward_backward

    def spying(*args, backend="numpy", **kwargs):
        seen.append(backend)
        return real(*args, backend=backend, **kwargs)

    monkeypatch.setattr(irl.inference.api, "forward_backward", spying)
    r = run_trial(Trial("sorting", method, 0.2, 0.3, 0, 2, 6, 0, backend="numba"))
    assert r.backend == "numba"
    (est,) = built
    if TAKES_BACKEND[method]:
        assert est.backend == "numba"
        # bc counts pairs and runs no forward-backward
        assert set(seen) == (set() if method == "bc" else {"numba"})
    else:  # not the learner; HiddenDataEM's passes run numpy
        assert not hasattr(est, "backend") and set(seen) <= {"numpy"}


def test_a_sweep_refuses_a_backend_that_cannot_run(numba_missing):
    with pytest.raises(ValueError, match="got 'cuda'"):
        SweepConfig("sorting", ((0.2, 0.3),), backend="cuda")
    with pytest.raises(ValueError, match=NUMBA_MISSING):
        SweepConfig("sorting", ((0.2, 0.3),), backend="numba")
    assert SweepConfig("sorting", ((0.2, 0.3),)).backend == "numpy"


def test_numba_and_numpy_sweeps_agree(built):
    """Every learner at two points, on both backends: the same weights and scores to 1e-9."""
    pytest.importorskip("numba")
    runs = {}
    for backend in ("numpy", "numba"):
        built.clear()
        cfg = SweepConfig("sorting", ((0.2, 0.3), (0.4, 0.45)), methods=METHODS, batches=1,
                          trajectories=3, length=10, seed=3, backend=backend)
        results = list(run_sweep(cfg))
        # behaviour cloning has no weights: its policy's probabilities stand for them
        runs[backend] = results, [e.action_probabilities_ if e.theta_ is None else e.theta_
                                  for e in built]
    (ref, ref_theta), (fast, fast_theta) = runs["numpy"], runs["numba"]
    assert [r.backend for r in ref] == ["numpy"] * len(ref)
    assert [r.backend for r in fast] == ["numba"] * len(fast)
    for a, b, ta, tb in zip(ref, fast, ref_theta, fast_theta, strict=True):
        assert (a.method, a.occlusion, a.noise, a.n_iter, a.converged, a.exact_policy) == \
            (b.method, b.occlusion, b.noise, b.n_iter, b.converged, b.exact_policy)
        np.testing.assert_allclose(tb, ta, rtol=0, atol=1e-9, err_msg=a.method)
        assert b.ile == pytest.approx(a.ile, rel=1e-9, abs=1e-9)
        assert b.normalized_ile == pytest.approx(a.normalized_ile, rel=1e-9, abs=1e-9)
