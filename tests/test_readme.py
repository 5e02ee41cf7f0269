"""The documented code stays true: the README's library example and the docs' examples run as
written."""

import doctest
import re
from pathlib import Path

import numpy as np
import pytest

import irl

ROOT = Path(__file__).parents[1]


def test_readme_library_example_runs(capsys):
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    example = next(b for b in blocks if "irl.MMAPBIRL" in b)
    scope: dict = {}
    exec(compile(example, "README.md", "exec"), scope)
    ile, loglik = map(float, capsys.readouterr().out.split())
    assert ile == 0.0  # 12 demonstrations at 30% noise recover the expert's policy
    est, demos = scope["est"], scope["demos"]
    assert loglik == pytest.approx(est.log_likelihood(est.theta_, demos), rel=1e-12)
    # the fitted reward explains the observations better than no reward (a uniform policy)
    assert loglik > est.log_likelihood(0.0 * est.theta_, demos) + 10


def test_package_docstring_example():
    failures, _ = doctest.testmod(irl, verbose=False)
    assert failures == 0


@pytest.mark.slow
def test_readme_stages_example_runs(tmp_path, monkeypatch):
    text = (ROOT / "docs" / "api.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    example = next(b for b in blocks if "onionsort.stages import" in b)
    monkeypatch.chdir(tmp_path)
    scope: dict = {}
    exec(compile(example, "docs/api.md", "exec"), scope)
    assert len(scope["sessions"]) == 4
    assert len(scope["model"]["policy_indices"]) == 48
    assert (tmp_path / "runs/study/mmap/model.json").is_file()


@pytest.mark.slow
def test_readme_gymnasium_example_matches_evaluate(capsys):
    from irl.domains.onion_sorting import onion_sorting
    from robot.evaluation import evaluate_policy

    text = (ROOT / "docs" / "api.md").read_text()
    example = next(b for b in re.findall(r"```python\n(.*?)```", text, flags=re.S)
                   if "Sorting-v0" in b)
    scope: dict = {}
    exec(compile(example, "docs/api.md", "exec"), scope)
    counts = [int(x) for x in capsys.readouterr().out.split()[-4:]]
    result = evaluate_policy(onion_sorting().expert_policy(), n_onions=6, n_blemished=3, seed=0,
                             classify=scope["inspector"])
    assert counts == [result.tp, result.fp, result.tn, result.fn]


@pytest.mark.slow
def test_readme_scale_example_runs_and_backends_agree(capsys):
    """The 10,000-state example of docs/performance.md: its fit recovers the true weights'
    signs and order (as the page prints), and the default backend finds the same weights."""
    pytest.importorskip("numba")
    text = (ROOT / "docs" / "performance.md").read_text()
    example = next(b for b in re.findall(r"```python\n(.*?)```", text, flags=re.S)
                   if "grid_mdp" in b)
    scope: dict = {}
    exec(compile(example, "docs/performance.md", "exec"), scope)
    theta = scope["est"].theta_
    np.testing.assert_allclose(theta, [1.09, -0.59, 0.54, -0.41], atol=0.005)
    numpy_fit = irl.MMAPBIRL(scope["mdp"], scope["sensor"]).fit(scope["demos"])
    np.testing.assert_allclose(numpy_fit.theta_, theta, rtol=1e-8, atol=1e-10)
