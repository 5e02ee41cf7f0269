"""Fixtures shared by the test packages."""

import pytest


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
