"""Fixtures shared by the test packages."""

import os

import pytest


@pytest.fixture(scope="session")
def ray():
    """A local Ray instance of 2 CPUs for the session's Ray tests. Skipped where Ray (the
    ``ray`` extra) is not installed, except in CI (``ONIONSORT_REQUIRE_RAY=1``), which
    installs it: there a missing Ray fails."""
    if os.environ.get("ONIONSORT_REQUIRE_RAY") == "1":
        import ray
    else:
        ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False)
    yield ray
    ray.shutdown()


@pytest.fixture
def built(monkeypatch):
    """The estimators that ``run_trial``, ``learn`` and ``experiment`` build (all through
    ``irl.experiments.make_estimator``), fitted, in order."""
    import irl.experiments

    real, estimators = irl.experiments.make_estimator, []

    def recording(*args, **kwargs):
        estimators.append(real(*args, **kwargs))
        return estimators[-1]

    monkeypatch.setattr(irl.experiments, "make_estimator", recording)
    return estimators
