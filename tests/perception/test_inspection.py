"""The inspection: fusing views, the cost threshold, calibration, crops, the classifier."""

from types import SimpleNamespace as NS

import numpy as np
import pytest
import torch

from perception.fusion import (
    chance_calibration_error,
    cost_threshold,
    expected_calibration_error,
    fuse,
    log_odds,
    precision_recall_curve,
    settled,
)
from perception.inspection import (
    CROP_SIZE,
    InspectionClassifier,
    InspectionNet,
    InspectionNetConfig,
    Inspector,
    crop_onion,
    fit_platt,
    fit_temperature,
    rot_label,
)
from perception.train_inspection import (
    CONTEXT_SIZE,
    CropSet,
    InspectionTrainConfig,
    augment,
    train_inspection,
)

#: What a view of a clean side says under each rule: noisy-or reads "rot in this view" (none:
#: near 0); log-odds reads "this onion is blemished" (a clean side still leaves a blemished
#: onion likely: many show one)
CLEAN_SIDE = {"noisy-or": 0.04, "log-odds": 0.25}
ROT_IN_VIEW = {"noisy-or": 0.99, "log-odds": 0.97}


@pytest.mark.parametrize("rule", ["noisy-or", "log-odds"])
def test_a_blemish_seen_in_one_of_three_views_is_found(rule):
    # the two other views see a clean side: the rot in one view still decides
    clean, rot = CLEAN_SIDE[rule], ROT_IN_VIEW[rule]
    assert fuse([clean, rot, clean], rule) >= 0.5
    assert fuse([rot, clean, clean], rule) == pytest.approx(fuse([clean, clean, rot], rule))


@pytest.mark.parametrize("rule", ["noisy-or", "log-odds"])
def test_a_good_onion_seen_three_times_stays_good(rule):
    clean = CLEAN_SIDE[rule]
    assert fuse([clean] * 3, rule) < 0.5
    assert fuse([clean] * 3, rule) <= fuse([clean], rule) + 0.15  # more views, not more doubt


def test_the_fusion_rules_are_what_they_say():
    p = [0.2, 0.5, 0.9]
    # noisy-or: each view of a blemished onion shows its rot with probability v
    v, ratio = 0.7, np.array([(q / (1 - q)) / (0.4 / 0.6) for q in p])
    odds = (0.3 / 0.7) * np.prod(1 - v + v * ratio)
    assert fuse(p, "noisy-or", prior=0.3, train_prior=0.4, visibility=v) == pytest.approx(
        odds / (1 + odds))
    # a clean view lowers the odds by 1 - v at most; with every view showing rot (v = 1) one
    # clean view clears the onion
    assert fuse([0.5], "noisy-or", visibility=0.6) == pytest.approx(0.5)
    assert fuse([0.999, 1e-6], "noisy-or", visibility=1.0) < 0.01
    with pytest.raises(ValueError, match="visibility"):
        fuse([0.5], "noisy-or", visibility=0.0)
    # log-odds: the line's prior odds times each view's likelihood ratio
    odds = (0.3 / 0.7) * np.prod([(q / (1 - q)) / 1.0 for q in p])
    assert fuse(p, "log-odds", prior=0.3, train_prior=0.5) == pytest.approx(odds / (1 + odds))
    # a view calibrated to another class balance: its prior is divided out
    assert fuse([0.75], "log-odds", prior=0.5, train_prior=0.75) == pytest.approx(0.5)
    for bad, match in (([], "at least one"), ([1.2], r"\[0, 1\]"), ([0.5, np.nan], r"\[0, 1\]")):
        with pytest.raises(ValueError, match=match):
            fuse(bad)
    with pytest.raises(ValueError, match="rule"):
        fuse([0.5], "max")
    with pytest.raises(ValueError, match="prior"):
        fuse([0.5], "log-odds", prior=1.0)


def test_the_threshold_follows_the_costs():
    assert cost_threshold(miss=8, waste=8) == 0.5
    assert cost_threshold(miss=3, waste=1) == 0.25  # missing rot costs more: bin sooner
    assert cost_threshold(miss=1, waste=3) == 0.75
    assert cost_threshold(miss=0, waste=1) == 1.0 and cost_threshold(miss=1, waste=0) == 0.0
    cuts = [cost_threshold(miss=m, waste=1.0) for m in (0.5, 1, 2, 4, 8)]
    assert cuts == sorted(cuts, reverse=True)
    for kwargs, match in (({"miss": -1, "waste": 1}, "miss"), ({"miss": 1, "waste": np.inf},
                                                               "waste"),
                          ({"miss": 0, "waste": 0}, "both be 0")):
        with pytest.raises(ValueError, match=match):
            cost_threshold(**kwargs)


def test_the_default_threshold_comes_from_the_tasks_reward():
    from irl.domains.onion_sorting import TRUE_THETA, misplacement_costs
    from onionsort.configs.common import sorting_threshold

    assert misplacement_costs() == (8.0, 8.0)
    assert sorting_threshold() == 0.5 and sorting_threshold(miss=3, waste=1) == 0.25
    theta = TRUE_THETA.copy()
    theta[3] = 10.0  # binning a blemished onion is worth more: missing one costs more
    miss, waste = misplacement_costs(theta)
    assert miss == 14.0 and waste == 8.0
    theta[0] = -5.0  # a reward that prefers binning good onions is no sorting task
    with pytest.raises(ValueError, match="misplacing"):
        misplacement_costs(theta)


def test_the_chance_calibration_error_is_what_a_calibrated_model_shows_on_so_few():
    """ECE's floor by chance: the median ECE of labels drawn from the probabilities; it falls
    as the onions grow in number, is reproducible from its seed, and a calibrated model's
    measured ECE sits about at it while a miscalibrated one's sits far above."""
    rng = np.random.default_rng(1)
    p = rng.uniform(0, 0.6, 60)
    floor = chance_calibration_error(p)
    assert chance_calibration_error(p) == floor  # the same seed, the same figure
    big = rng.uniform(0, 1, 6000)
    assert chance_calibration_error(big) < floor / 4  # about 1/sqrt(N)
    assert 0.04 < floor < 0.2  # 60 onions in 15 bins: a few each
    calibrated = [expected_calibration_error(p, rng.random(p.size) < p) for _ in range(300)]
    assert np.mean(np.array(calibrated) <= floor) == pytest.approx(0.5, abs=0.1)
    off = [expected_calibration_error(p + 0.4, rng.random(p.size) < p)
           for _ in range(50)]
    assert min(off) > 2 * floor
    with pytest.raises(ValueError, match="probabilities in"):
        chance_calibration_error([0.2, 1.5])
    with pytest.raises(ValueError, match="non-empty"):
        chance_calibration_error([])


def test_the_check_against_chance_passes_a_calibrated_model_as_often_as_its_quantile():
    """calibration_within_chance: a perfectly calibrated model (labels drawn from its own
    probabilities) passes about as often as the quantile says, on 300 onions as on 60; one
    that hedges (the probabilities of the section's robot: blemished onions at 0.6-0.9, all
    of them blemished) fails on 300 onions; the figures are the chance errors' quantiles,
    reproducible from the seed."""
    from perception.fusion import calibration_within_chance, chance_calibration_errors

    rng = np.random.default_rng(5)
    for n in (60, 300):
        p = np.r_[rng.uniform(0.0, 0.05, n // 2), rng.uniform(0.85, 1.0, n // 2)]
        passed = [calibration_within_chance(p, rng.random(n) < p, draws=200, seed=i)["within"]
                  for i in range(400)]
        assert np.mean(passed) == pytest.approx(0.9, abs=0.045)
    check = calibration_within_chance(p, rng.random(p.size) < p)
    errors = chance_calibration_errors(p, draws=1000)
    assert check["chance_quantile"] == pytest.approx(np.quantile(errors, 0.9))
    assert check["chance_median"] == pytest.approx(np.median(errors))
    assert check["chance_median"] < check["chance_quantile"] and check["onions"] == 300
    assert chance_calibration_error(p, draws=1000, quantile=0.9) == check["chance_quantile"]
    assert calibration_within_chance(p, rng.random(p.size) < p) != check  # fresh labels
    hedged = np.r_[rng.uniform(0.0, 0.05, 150), rng.uniform(0.6, 0.9, 150)]
    y = np.r_[np.zeros(150), np.ones(150)]
    assert not calibration_within_chance(hedged, y)["within"]
    with pytest.raises(ValueError, match="labels 0 or 1"):
        calibration_within_chance([0.2, 0.4], [0, 2])
    with pytest.raises(ValueError, match="quantile"):
        calibration_within_chance([0.2, 0.4], [0, 1], quantile=1.5)
    with pytest.raises(ValueError, match="draws"):
        chance_calibration_errors([0.2, 0.4], draws=0)


def test_expected_calibration_error_and_the_precision_recall_curve():
    rng = np.random.default_rng(0)
    p = rng.uniform(0, 1, 20_000)
    y = rng.random(20_000) < p  # calibrated by construction
    assert expected_calibration_error(p, y) < 0.02
    assert expected_calibration_error(np.where(p > 0.5, 0.99, 0.01), y) > 0.2
    # one bin: |mean(y) - mean(p)|
    assert expected_calibration_error([0.9, 0.9], [1, 0], n_bins=1) == pytest.approx(0.4)
    precision, recall, cut = precision_recall_curve([0.9, 0.8, 0.8, 0.1], [1, 0, 1, 0])
    np.testing.assert_allclose(cut, [0.9, 0.8, 0.1])
    np.testing.assert_allclose(precision, [1.0, 2 / 3, 0.5])
    np.testing.assert_allclose(recall, [0.5, 1.0, 1.0])


def test_temperature_and_platt_scaling_recover_what_made_the_labels():
    rng = np.random.default_rng(1)
    z = rng.normal(0, 3, 8000)
    y = rng.random(8000) < 1 / (1 + np.exp(-z / 2.5))
    assert fit_temperature(z, y) == pytest.approx(2.5, rel=0.08)
    y2 = rng.random(8000) < 1 / (1 + np.exp(-(0.5 * z - 1.0)))
    a, b = fit_platt(z, y2)
    assert a == pytest.approx(0.5, abs=0.05) and b == pytest.approx(-1.0, abs=0.1)
    # uninformative logits: the temperature stops at its bound, every probability near 1/2
    assert fit_temperature(np.ones(100), np.arange(100) % 2) == pytest.approx(100.0)
    with pytest.raises(ValueError, match="one length"):
        fit_temperature(np.ones(3), np.ones(2))


def test_a_view_is_labelled_by_the_rot_it_shows():
    assert rot_label(0, 10_000, True) == 0  # a blemished onion, its rot out of sight
    assert rot_label(500, 10_000, True) == 1
    assert rot_label(20, 10_000, True) == -1  # a sliver at the rim: unclear
    assert rot_label(None, 10_000, True) == 1  # not measured: the onion's class stands in


def test_crops_centre_the_box_and_average_a_large_view():
    rgb = np.zeros((240, 320, 3), np.uint8)
    rgb[100:140, 150:190] = 200  # the "onion"
    crop = crop_onion(rgb, (150, 100, 190, 140), margin=0.0)
    assert crop.shape == (CROP_SIZE, CROP_SIZE, 3) and crop[2:-2, 2:-2].min() > 190
    # a box at the border: the outside repeats the image's edge, the crop keeps its size
    assert crop_onion(rgb, (0, 0, 30, 30)).shape == (CROP_SIZE, CROP_SIZE, 3)
    noise = np.random.default_rng(0).normal(128, 30, (240, 320, 3)).clip(0, 255)
    shrunk = crop_onion(noise.astype(np.uint8), (60, 20, 260, 220))
    assert shrunk.std() < 30 / 2  # area averaging of a 200-pixel window into 64


def _blob_crops(n, rng, size):
    """Synthetic views: a bright disc, with a dark patch on it in the positives."""
    v, u = np.mgrid[0:size, 0:size]
    c = size / 2
    crops, labels = [], []
    for k in range(n):
        img = np.full((size, size, 3), 240.0)
        disc = (u - c) ** 2 + (v - c) ** 2 < (0.3 * size) ** 2
        img[disc] = [190, 140, 70]
        if k % 2:
            a = rng.uniform(0, 2 * np.pi)
            cx, cy = c + 0.15 * size * np.cos(a), c + 0.15 * size * np.sin(a)
            img[(u - cx) ** 2 + (v - cy) ** 2 < (0.06 * size) ** 2] = [50, 35, 20]
        img += rng.normal(0, 8, img.shape)
        crops.append(img.clip(0, 255).astype(np.uint8))
        labels.append(k % 2)
    return np.stack(crops), np.array(labels)


def test_the_classifier_learns_to_see_rot_and_its_checkpoint_round_trips(tmp_path):
    rng = np.random.default_rng(0)
    train_x, train_y = _blob_crops(160, rng, CONTEXT_SIZE)
    val_x, val_y = _blob_crops(60, rng, CROP_SIZE)
    net = InspectionNetConfig(width=8)
    clf, metrics = train_inspection(
        CropSet(train_x, train_y, train_y, np.ones(len(train_y))),
        CropSet(val_x, val_y, val_y, np.ones(len(val_y))),
        InspectionTrainConfig(epochs=6, batch_size=32, lr=5e-3), net)
    assert metrics["val"]["accuracy"] >= 0.9, metrics["history"]
    p = clf.rot_probabilities(val_x)
    assert ((p >= 0.5) == (val_y == 1)).mean() >= 0.9
    path = clf.save(tmp_path / "inspection_classifier.pt")
    again = InspectionClassifier.load(path)
    np.testing.assert_allclose(again.probabilities(val_x), clf.probabilities(val_x))
    assert again.rule == clf.rule and again.temperature == clf.temperature
    (tmp_path / "bad.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match="not an inspection classifier"):
        InspectionClassifier.load(tmp_path / "bad.pt")
    torch.save({"kind": "detector"}, tmp_path / "other.pt")
    with pytest.raises(ValueError, match="not an inspection classifier"):
        InspectionClassifier.load(tmp_path / "other.pt")


def test_augmented_crops_are_crops():
    context = np.random.default_rng(0).integers(0, 255, (CONTEXT_SIZE, CONTEXT_SIZE, 3),
                                                 dtype=np.uint8)
    crop = augment(context, np.random.default_rng(1), InspectionTrainConfig())
    assert crop.shape == (CROP_SIZE, CROP_SIZE, 3) and crop.dtype == np.uint8


class _FakeDetector:
    """Finds the onion in views whose mean is above 10, with a box round the middle."""

    def detect(self, images):
        out = []
        for img in images:
            h, w = img.shape[:2]
            found = int(img.mean() > 10)
            out.append(NS(boxes=np.array([[w / 4, h / 4, 3 * w / 4, 3 * h / 4]] * found),
                          scores=np.array([0.9] * found), classes=np.array([0] * found)))
        return out


def test_the_inspector_fuses_the_views_it_finds_and_calls_at_the_threshold():
    torch.manual_seed(0)
    clf = InspectionClassifier(InspectionNet(InspectionNetConfig(width=4)))
    blank = np.zeros((120, 160, 3), np.uint8)
    onion = np.full((120, 160, 3), 128, np.uint8)
    p = clf.view_probabilities([crop_onion(onion, (40, 30, 120, 90))], "log-odds")[0]
    low = Inspector(_FakeDetector(), clf, rule="log-odds", threshold=max(0.01, p / 4))
    high = Inspector(_FakeDetector(), clf, rule="log-odds", threshold=min(0.99, 1 - (1 - p) / 4))
    verdict = low([blank, onion, blank])
    assert verdict.view_p_blemished[0] is None and verdict.view_p_blemished[2] is None
    assert verdict.p_blemished == pytest.approx(p, rel=1e-5)
    assert verdict.prediction == 1 and high([onion]).prediction == 0
    none = low([blank, blank])
    assert none.prediction == 2 and none.p_blemished is None  # unknown: no view showed it
    assert low.last_detections([blank, blank]) is not None
    assert low.last_detections([onion, blank]) is not None  # read one call before
    unseen = np.full((120, 160, 3), 77, np.uint8)
    assert low.last_detections([unseen]) is None  # never read
    calls = []
    low.detector.detect = lambda views, detect=low.detector.detect: calls.append(len(views)) \
        or detect(views)
    both = low.detections([onion, unseen])  # the onion's as read before; only the new detected
    assert calls == [1] and len(both) == 2 and len(both[0].scores) == len(both[1].scores) == 1
    with pytest.raises(ValueError, match="threshold"):
        Inspector(_FakeDetector(), clf, threshold=1.0)
    with pytest.raises(ValueError, match="rule"):
        Inspector(_FakeDetector(), clf, rule="mean")


@pytest.mark.parametrize("rule", ["noisy-or", "log-odds"])
def test_a_settled_call_is_the_call_after_every_view(rule):
    """Whatever the views still to come show (or if they miss the onion), the call on an
    onion settled after k of K views is the call after all K."""
    rng = np.random.default_rng(0)
    n_settled = 0
    for _ in range(300):
        k_all = int(rng.integers(1, 7))
        kw = {"prior": rng.uniform(0.2, 0.8), "train_prior": rng.uniform(0.2, 0.8),
              "visibility": rng.uniform(0.2, 1.0)}
        threshold = rng.uniform(0.1, 0.9)
        # views near 0, near 1 or in between, as a real classifier's
        views = rng.choice([1e-7, 0.02, 0.3, 0.7, 0.98, 1 - 1e-7], size=k_all)
        for k in range(k_all + 1):
            if not settled(views[:k], k_all - k, rule, threshold=threshold, **kw):
                continue
            n_settled += k < k_all
            call = log_odds(views[:k], rule, **kw) >= np.log(threshold / (1 - threshold))
            for rest in (np.zeros(k_all - k), np.ones(k_all - k), rng.uniform(size=k_all - k),
                         np.zeros(0)):  # the last: the remaining views all miss the onion
                seen = np.r_[views[:k], rest]
                assert (log_odds(seen, rule, **kw) >= np.log(threshold / (1 - threshold))
                        if not len(seen) else fuse(seen, rule, **kw) >= threshold) == call
    assert n_settled > 50  # it settles early often enough to matter


def test_under_noisy_or_a_view_showing_rot_settles_a_blemish_and_nothing_settles_a_good_one():
    kw = {"prior": 0.5, "train_prior": 0.5, "visibility": 0.3}
    assert settled([0.999], 4, "noisy-or", **kw)  # a clean view lowers the odds by 0.7 at most
    assert not settled([0.6], 4, "noisy-or", **kw)  # a hint is not enough yet
    assert not settled([0.01] * 4, 1, "noisy-or", **kw)  # one more view could show rot
    assert settled([0.01] * 4, 0, "noisy-or", **kw)  # nothing left to see
    assert not settled([], 1, "noisy-or", **kw) and settled([], 0, "noisy-or", **kw)
    with pytest.raises(ValueError, match="remaining"):
        settled([0.5], -1)
    with pytest.raises(ValueError, match="threshold"):
        settled([0.5], 1, threshold=1.0)


def test_the_inspector_reads_views_one_at_a_time_as_it_reads_them_together():
    torch.manual_seed(0)
    clf = InspectionClassifier(InspectionNet(InspectionNetConfig(width=4)), visibility=0.5)
    views = [np.zeros((120, 160, 3), np.uint8),
             *(np.full((120, 160, 3), g, np.uint8) for g in (90, 128, 200))]
    inspector = Inspector(_FakeDetector(), clf, rule="noisy-or")
    one_by_one = [p for v in views for p in inspector.view_probabilities([v])]
    together_p = inspector.view_probabilities(views)
    assert one_by_one[0] is None and together_p[0] is None  # the blank view shows no onion
    assert one_by_one[1:] == pytest.approx(together_p[1:], rel=1e-5)
    together, alone = inspector(views), inspector.verdict(one_by_one)
    assert alone.prediction == together.prediction
    assert alone.p_blemished == pytest.approx(together.p_blemished, rel=1e-5)
    seen = [p for p in one_by_one if p is not None]
    assert inspector.settled(one_by_one, 2) == settled(
        seen, 2, "noisy-or", threshold=0.5, prior=0.5, train_prior=clf.rot_prior,
        visibility=0.5)


def test_an_onion_no_view_has_shown_is_never_settled_while_views_remain():
    # the call is "unknown" until the detector finds the onion; a steep miss cost (a low
    # threshold) must not end the inspection on the prior alone
    torch.manual_seed(0)
    clf = InspectionClassifier(InspectionNet(InspectionNetConfig(width=4)), visibility=0.3)
    low = Inspector(_FakeDetector(), clf, rule="noisy-or", threshold=0.19)
    assert settled([], 4, "noisy-or", threshold=0.19, visibility=0.3)  # the prior alone would
    assert fuse([0.0] * 4, "noisy-or", visibility=0.3) >= 0.19  # but clean views still bin it
    assert not low.settled([None], 4) and low.settled([None], 0)
    assert low.verdict([None]).prediction == 2
    # a threshold below the clipping of probabilities is compared as it is
    assert not settled([1e-6, 1e-6], 1, "log-odds", threshold=1e-7, prior=0.3)
