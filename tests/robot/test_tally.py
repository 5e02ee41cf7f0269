"""Counting a sorted line-up: fates, TP/FP/TN/FN, and precision and recall with their 95%
Wilson intervals (checked against scipy's)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binomtest

from irl.domains.onion_sorting import Prediction
from robot.tally import SortingCounts, SortingTally, count_fates, wilson_interval


@pytest.mark.parametrize(("k", "n"), [(30, 30), (0, 7), (3, 4), (17, 50), (1, 1), (250, 400)])
def test_the_wilson_interval_is_scipys(k, n):
    ci = binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
    np.testing.assert_allclose(wilson_interval(k, n), (ci.low, ci.high), rtol=0, atol=1e-12)


def test_the_wilson_interval_of_all_or_none_reaches_its_edge_exactly():
    assert wilson_interval(30, 30)[1] == 1.0 and wilson_interval(0, 30)[0] == 0.0


def test_the_wilson_interval_of_nothing_is_everything_and_bad_counts_are_refused():
    assert wilson_interval(0, 0) == (0.0, 1.0)
    for k, n in ((3, 2), (-1, 4), (1.5, 3), (True, 3)):
        with pytest.raises(ValueError):
            wilson_interval(k, n)


def test_fates_are_counted_by_class_and_deferred_apart():
    counts = count_fates([True, True, False, False, True, False],
                         ["bin", "line", "bin", "line", "tray", "tray"])
    assert counts == SortingCounts(tp=1, fp=1, tn=1, fn=1, deferred=2)
    assert counts.n_onions == 6 and counts.deferral_rate == pytest.approx(1 / 3)
    doc = counts.to_dict()
    assert doc["precision"] == doc["recall"] == 0.5
    assert doc["precision_ci"] == list(wilson_interval(1, 2))
    assert "precision 0.500 [0.095, 0.905]" in counts.table()
    assert "deferred to a person: 2" in counts.table()
    with pytest.raises(ValueError, match="a fate must be one of bin, line, tray; got 'floor'"):
        count_fates([True], ["floor"])
    with pytest.raises(ValueError, match="one entry per onion"):
        count_fates([True, False], ["bin"])


def test_a_tally_counts_each_fate_once_and_scores_only_with_the_truth():
    tally = SortingTally(3, np.array([True, False, True]))
    tally.inspected(0, Prediction.BAD, 0.9, 5)
    assert tally.decide(0, "bin") and not tally.decide(0, "line")
    assert tally.decide(1, "tray")
    assert tally.counts == {"tp": 1, "fp": 0, "tn": 0, "fn": 0} and not tally.complete
    result = tally.result(n_steps=9)
    assert (result.tp, result.fn, result.deferred, result.undecided) == (1, 1, 1, 1)
    assert result.onions[0].p_blemished == 0.9 and result.onions[0].views == 5
    assert result.to_dict()["recall_ci"] == list(wilson_interval(1, 2))
    blind = SortingTally(2)
    assert blind.decide(0, "bin") and blind.counts["tp"] == 0
    with pytest.raises(ValueError, match="true classes are unknown"):
        blind.result(n_steps=1)
    with pytest.raises(ValueError, match=r"shape \(3,\)"):
        SortingTally(3, np.zeros(2, bool))
