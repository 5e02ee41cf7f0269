"""Fixtures shared by the test packages."""

import contextlib
import io
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


@pytest.fixture(scope="session")
def run_tool():
    """``run_tool(name, script, *args, env=None)``: a tool of another project (Label Studio's
    SDK, Ultralytics) reading our files in a child process (:func:`tests.tools.run_tool`), the
    tool installed on first use into a folder of its own. Skipped where it cannot be installed
    (no package registry), except in CI (``ONIONSORT_REQUIRE_TOOLS=1``): there it fails."""
    from tests import tools

    def run(name, script, *args, env=None):
        try:
            tools.install(name)
        except RuntimeError as exc:
            if os.environ.get("ONIONSORT_REQUIRE_TOOLS") == "1":
                raise
            pytest.skip(str(exc))
        return tools.run_tool(name, script, *args, env=env)

    return run


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


@pytest.fixture(scope="session")
def quick_demo(tmp_path_factory):
    """``(folder, printed)``: a finished ``onionsort demo --quick`` run folder and what the
    command printed, run once per test session for the tests that read it (the end-to-end smoke
    test, the report). Tests may add files to it but must not change the demo's own."""
    from onionsort.cli import main

    out = tmp_path_factory.mktemp("quick-demo") / "demo"
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        code = main(["demo", "--quick", "--out", str(out)])
    assert code == 0, printed.getvalue()
    return out, printed.getvalue()


@pytest.fixture(scope="module")
def perceived_sessions(tmp_path_factory):
    """Two perceived sessions of 10 steps (20% occluded) without the simulator: sensor frames
    of plain arrays, observations drawn from the sorting expert through a 30%-noise sensor."""
    import numpy as np

    from irl.demonstrations import observe, sample_trajectory
    from irl.domains import onion_sorting
    from recordings.session.perception import add_perception
    from tests.test_bad_cli import _sensor_session

    folder, dom, paths = tmp_path_factory.mktemp("perceived"), onion_sorting(noise=0.3), []
    for i in range(2):
        rng = np.random.default_rng(i)
        demo = observe(sample_trajectory(dom.mdp, dom.expert_policy(), 10, rng),
                       dom.observation_model, 0.2, rng)
        obs = demo.as_array()
        path = _sensor_session(folder / f"session_{i:03d}.mcap", frames_per_step=1,
                               steps=len(obs))
        steps = [{"step": t, "frame": t, "occluded": bool(o < 0),
                  "observation": None if o < 0 else int(o)} for t, o in enumerate(obs)]
        add_perception(path, steps, detections={}, inspection={},
                       frame_times={t: t * 10**8 for t in range(len(obs))},
                       models={"folder": "test"})
        paths.append(path)
    return paths
