"""``onionsort eval-posterior``: the posterior's credible action sets and its confidence scored
against the expert on synthetic problems (the stage :mod:`onionsort.stages.eval_posterior`)."""

import itertools
import json

import numpy as np
import pytest

from onionsort.cli import main
from onionsort.stages.eval_posterior import auroc


def _pairwise_auroc(scores, labels) -> float:
    """The AUROC by its definition: the share of (positive, negative) pairs that the scores
    order rightly, a tie counting one half."""
    pos = [s for s, y in zip(scores, labels, strict=True) if y]
    neg = [s for s, y in zip(scores, labels, strict=True) if not y]
    wins = [1.0 if p > n else 0.5 if p == n else 0.0 for p, n in itertools.product(pos, neg)]
    return float(np.mean(wins))


def test_auroc_is_the_share_of_pairs_ordered_rightly_ties_halved():
    rng = np.random.default_rng(3)
    for _ in range(20):
        scores = rng.integers(0, 5, 30) / 4  # many ties
        labels = rng.random(30) < 0.3
        if labels.all() or not labels.any():
            continue
        assert auroc(scores, labels) == pytest.approx(_pairwise_auroc(scores, labels))
    assert auroc([0.1, 0.9], [False, True]) == 1.0
    assert auroc([0.5, 0.5], [False, True]) == 0.5
    assert auroc([0.3, 0.4], [True, True]) is None  # no negatives


def test_laplace_scores_on_sorting_are_the_documented_ones(capsys):
    """docs/posterior.md quotes ``onionsort eval-posterior sorting --method laplace``: 40
    problems (seeds 1000-1039); the scores do not depend on the machine."""
    assert main(["eval-posterior", "sorting", "--method", "laplace", "--workers", "1",
                 "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    visited, every = r["visited"], r["all"]
    assert (visited["pairs"], visited["map_wrong"]) == (268, 3)
    assert (every["pairs"], every["map_wrong"]) == (1920, 104)
    assert [round(v, 3) for v in visited["coverage"].values()] == [0.993, 0.993, 1.0, 1.0]
    assert round(visited["mean_set_size"]["0.90"], 2) == 1.31
    assert round(visited["auroc"], 3) == 0.957
    assert [round(v, 3) for v in every["coverage"].values()] == [0.95, 0.963, 1.0, 1.0]
    assert round(every["auroc"], 3) == 0.919
    assert r["max_r_hat"] == [None] * 40 and len(r["seconds"]) == 40


def test_the_scores_do_not_depend_on_the_workers_and_the_text_says_them(capsys):
    argv = ["eval-posterior", "forestworld", "--method", "laplace", "--problems", "4",
            "--noise", "0.3", "--samples", "200", "--json"]
    results = []
    for workers in ("1", "2"):
        assert main([*argv, "--workers", workers]) == 0
        r = json.loads(capsys.readouterr().out)
        r.pop("seconds")
        results.append(r)
    assert results[0] == results[1]
    r = results[0]
    assert r["config"]["domain"] == "forestworld" and r["config"]["problems"] == 4
    for scope in ("visited", "all"):
        s = r[scope]
        assert s["map_wrong"] + s["map_right"] == s["pairs"]
        cover = list(s["coverage"].values())
        assert all(0.0 <= c <= 1.0 for c in cover)
        assert cover == sorted(cover)  # a higher level's sets hold a lower level's
        sizes = list(s["mean_set_size"].values())
        assert sizes == sorted(sizes) and sizes[0] >= 1.0
    assert r["all"]["pairs"] == 4 * 16  # forestworld's 16 states, every problem
    assert main([a for a in argv if a != "--json"] + ["--workers", "1"]) == 0
    text = capsys.readouterr().out
    assert "forestworld, noise 0.3: 4 problems of 2 demonstrations x 10 steps" in text
    assert f"{r['visited']['coverage']['0.90']:>10.3f}" in text
    assert "max R-hat: none (the Laplace draws are independent)" in text
