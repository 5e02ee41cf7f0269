"""The calibration of the robot's fused P(blemished): monotone, fitted, stored, applied."""

import json
import shutil

import numpy as np
import pytest

from perception.fusion import (
    FUSION_RULES,
    check_calibration,
    expected_calibration_error,
    fuse,
    log_odds,
    settled,
)

CALIBRATIONS = [None, (0.4, 0.4), (2.5, 1.0), (3.0, 0.2), (4.6, 1.4, "log"), (0.5, 0.7, "log"),
                (1.6, 0.6, "powers", 1.5, 0.9), (0.5, 2.0, "powers", 0.3, 2.5)]


@pytest.mark.parametrize("rule", FUSION_RULES)
@pytest.mark.parametrize("calibration", CALIBRATIONS)
def test_more_blemished_evidence_never_lowers_the_calibrated_probability(rule, calibration):
    rng = np.random.default_rng(1)
    for _ in range(300):
        views = rng.choice([1e-7, 0.02, 0.3, 0.5, 0.7, 0.98, 1 - 1e-7], size=rng.integers(1, 6))
        kw = {"prior": rng.uniform(0.2, 0.8), "train_prior": rng.uniform(0.2, 0.8),
              "visibility": rng.uniform(0.2, 1.0), "calibration": calibration}
        before = fuse(views, rule, **kw)
        k = int(rng.integers(len(views)))
        more = views.copy()
        more[k] = rng.uniform(views[k], 1.0)  # one view says more of a blemish
        assert fuse(more, rule, **kw) >= before - 1e-12


@pytest.mark.parametrize("rule", FUSION_RULES)
def test_the_calibration_scales_the_fused_evidence_by_the_slope_of_its_side(rule):
    kw = {"prior": 0.3, "train_prior": 0.4, "visibility": 0.5}
    for views in ([0.1, 0.6, 0.03], [0.9, 0.99]):
        evidence = log_odds(views, rule, **kw) - np.log(0.3 / 0.7)
        slope = 1.7 if evidence < 0 else 0.2
        want = np.log(0.3 / 0.7) + slope * evidence
        assert log_odds(views, rule, calibration=(1.7, 0.2), **kw) == pytest.approx(want)
        assert fuse(views, rule, calibration=(1.7, 0.2), **kw) == pytest.approx(
            1 / (1 + np.exp(-want)))
        # "log" scales log(1 + |E|), its sign kept; "slopes" is the default form
        want = np.log(0.3 / 0.7) + slope * np.sign(evidence) * np.log1p(abs(evidence))
        assert log_odds(views, rule, calibration=(1.7, 0.2, "log"), **kw) == pytest.approx(want)
        assert log_odds(views, rule, calibration=(1.7, 0.2, "slopes"), **kw) == log_odds(
            views, rule, calibration=(1.7, 0.2), **kw)
        # "powers" scales |E| to its side's power: 1.5 below 0, 0.4 above
        power = 1.5 if evidence < 0 else 0.4
        want = np.log(0.3 / 0.7) + slope * np.sign(evidence) * abs(evidence) ** power
        assert log_odds(views, rule, calibration=(1.7, 0.2, "powers", 1.5, 0.4),
                        **kw) == pytest.approx(want)


@pytest.mark.parametrize("rule", FUSION_RULES)
@pytest.mark.parametrize("calibration", CALIBRATIONS[1:])
def test_a_settled_call_under_a_calibration_is_the_call_after_every_view(rule, calibration):
    rng = np.random.default_rng(2)
    n_settled = 0
    for _ in range(300):
        k_all = int(rng.integers(1, 6))
        kw = {"prior": 0.5, "train_prior": rng.uniform(0.2, 0.8),
              "visibility": rng.uniform(0.2, 1.0), "calibration": calibration}
        threshold = rng.uniform(0.1, 0.9)
        views = rng.choice([1e-7, 0.02, 0.3, 0.7, 0.98, 1 - 1e-7], size=k_all)
        for k in range(1, k_all + 1):
            if not settled(views[:k], k_all - k, rule, threshold=threshold, **kw):
                continue
            n_settled += k < k_all
            call = fuse(views[:k], rule, **kw) >= threshold
            for rest in (np.zeros(k_all - k), np.ones(k_all - k), rng.uniform(size=k_all - k),
                         np.zeros(0)):
                assert (fuse(np.r_[views[:k], rest], rule, **kw) >= threshold) == call
    assert n_settled > 20


def test_expected_calibration_error_on_a_hand_example():
    p, y = [0.1, 0.2, 0.8, 0.9], [0, 0, 1, 0]
    # 10 bins, one onion each: (0.1 + 0.2 + 0.2 + 0.9) / 4
    assert expected_calibration_error(p, y, n_bins=10) == pytest.approx(0.35)
    # 2 bins: |0 - 0.15| for two onions, |0.5 - 0.85| for two
    assert expected_calibration_error(p, y, n_bins=2) == pytest.approx((0.3 + 0.7) / 4)
    # good onions at 0.3 and blemished ones at 1: 0.3 over the good half
    assert expected_calibration_error([0.3] * 5 + [1.0] * 5, [0] * 5 + [1] * 5,
                                      n_bins=10) == pytest.approx(0.15)


@pytest.mark.parametrize("bad", [(0.0, 1.0), (1.0, -1.0), (np.nan, 1.0), (1.0, np.inf),
                                 (1.0,), "ab", 3.0, (1.0, 1.0, "isotonic"), (1.0, 1.0, 0.5),
                                 (1.0, 1.0, "log", "log"), (-1.0, 1.0, "log"),
                                 (1.0, 1.0, "powers"), (1.0, 1.0, "log", 1.0, 1.0),
                                 (1.0, 1.0, "powers", 0.0, 1.0), (1.0, 1.0, "powers", 1.0),
                                 (1.0, 1.0, "powers", 1.0, np.nan), (1.0, 1.0, 2.0, 1.0, 1.0)])
def test_a_calibration_that_is_not_monotone_or_not_two_slopes_and_a_form_is_refused(bad):
    with pytest.raises(ValueError, match="calibration must be") as err:
        check_calibration(bad)
    assert "\n" not in str(err.value)
    with pytest.raises(ValueError, match="calibration must be"):
        fuse([0.5], "noisy-or", calibration=bad)


def _views(evidence_p, classes):
    """Robot views (one per row) of onions ``o0, o1, ...``, as the stage groups them."""
    from onionsort.stages.inspection import InspectionViews

    n = len(classes)
    return InspectionViews(
        crops=np.zeros((n, 2, 2, 3), np.uint8), labels=np.asarray(classes),
        classes=np.asarray(classes), level=np.array(["clean"] * n),
        source=np.array(["robot"] * n), onion=np.array([f"o{i}" for i in range(n)]),
        view=np.zeros(n, int), found=np.ones(n, bool)), np.asarray(evidence_p, float)


def _classifier():
    from perception.inspection import InspectionClassifier, InspectionNet, InspectionNetConfig

    return InspectionClassifier(InspectionNet(InspectionNetConfig(width=8)), rot_prior=0.5,
                                visibility=0.3, rule="noisy-or")


def test_the_fit_sharpens_a_hedged_fusion_and_keeps_its_calls():
    from onionsort.stages.inspection import fit_fused_calibration

    # good onions at fused 0.3, blemished ones at 0.9, every call right: hedged both ways
    rng = np.random.default_rng(3)
    classes = np.r_[np.zeros(200, int), np.ones(200, int)]
    q = np.where(classes == 1, rng.uniform(0.6, 0.99, 400), rng.uniform(0.05, 0.4, 400))
    views, p = _views(q, classes)
    clf = _classifier()
    fitted = fit_fused_calibration(clf, views, {"noisy-or": p})["noisy-or"]
    assert fitted["low"] > 1 and fitted["high"] > 1
    assert fitted["ece_after"] < fitted["ece_before"]
    before = np.array([clf.fuse([x], "noisy-or") for x in p])
    clf.set_fused_calibration("noisy-or", (fitted["low"], fitted["high"], fitted["form"]))
    after = np.array([clf.fuse([x], "noisy-or") for x in p])
    np.testing.assert_array_equal(after >= 0.5, before >= 0.5)  # the same calls, surer
    assert expected_calibration_error(after, classes) == pytest.approx(fitted["ece_after"])
    with pytest.raises(ValueError, match="good and blemished onions"):
        fit_fused_calibration(clf, _views(q[:5], classes[:5])[0], {"noisy-or": p[:5]})


def test_the_robots_inspection_applies_the_calibration_its_models_folder_holds(tmp_path):
    from onionsort.stages.models import (
        DEFAULT_MODELS,
        ROBOT_FUSION_FILE,
        PerceptionModels,
        read_fused_calibration,
    )

    folder = tmp_path / "models"
    shutil.copytree(DEFAULT_MODELS, folder)
    (folder / ROBOT_FUSION_FILE).unlink(missing_ok=True)
    plain = PerceptionModels.load(folder, "cpu")
    assert plain.robot_inspection.fused_calibration == {}
    doc = {"format": 1, "rules": {"noisy-or": {"low": 2.0, "high": 0.5}}}
    (folder / ROBOT_FUSION_FILE).write_text(json.dumps(doc))
    assert read_fused_calibration(folder / ROBOT_FUSION_FILE) == {
        "noisy-or": (2.0, 0.5, "slopes")}
    models = PerceptionModels.load(folder, "cpu")
    assert models.robot_inspection.fused_calibration == {"noisy-or": (2.0, 0.5, "slopes")}
    assert models.inspection.fused_calibration == {}  # the sorter's fusion is left as it was
    inspector = models.inspector(camera="robot", rule="noisy-or")
    views = [0.02, 0.1, 0.05]
    raw = plain.inspector(camera="robot", rule="noisy-or").verdict(views)
    calibrated = inspector.verdict(views)
    evidence = log_odds(views, "noisy-or", train_prior=models.robot_inspection.rot_prior,
                        visibility=models.robot_inspection.visibility)
    assert calibrated.p_blemished == pytest.approx(1 / (1 + np.exp(-2.0 * evidence)))
    assert calibrated.p_blemished < raw.p_blemished < 0.5
    assert calibrated.prediction == raw.prediction
    doc["rules"]["noisy-or"]["form"] = "log"  # a form, where the file names one
    (folder / ROBOT_FUSION_FILE).write_text(json.dumps(doc))
    logged = PerceptionModels.load(folder, "cpu").inspector(camera="robot", rule="noisy-or")
    assert logged.verdict(views).p_blemished == pytest.approx(
        1 / (1 + np.exp(2.0 * np.log1p(-evidence))))
    # a file that is not one, or holds a map that is not monotone: one line naming it
    for text in ("not json", json.dumps({"rules": {"noisy-or": {"low": -1.0, "high": 1.0}}}),
                 json.dumps({"rules": {"noisy-or": {"low": 1.0, "high": 1.0, "form": "max"}}}),
                 json.dumps({"rules": {"noisy-or": {"low": 1.0, "high": 1.0, "form": "log",
                                                    "low_power": 2.0, "high_power": 1.0}}}),
                 json.dumps({"rules": {"max": {"low": 1.0, "high": 1.0}}})):
        (folder / ROBOT_FUSION_FILE).write_text(text)
        with pytest.raises(ValueError, match=ROBOT_FUSION_FILE) as err:
            PerceptionModels.load(folder, "cpu")
        assert "\n" not in str(err.value)


def test_a_line_of_a_level_applies_that_levels_own_calibration(tmp_path):
    from onionsort.stages.models import DEFAULT_MODELS, ROBOT_FUSION_FILE, PerceptionModels
    from robot.difficulty import DIFFICULTY_LEVELS

    folder = tmp_path / "models"
    shutil.copytree(DEFAULT_MODELS, folder)
    pooled, hard = (2.0, 0.5, "slopes"), (0.5, 3.0, "log")
    doc = {"format": 2, "rules": {"noisy-or": {"low": 2.0, "high": 0.5}},
           "levels": {"hard": {"noisy-or": {"low": 0.5, "high": 3.0, "form": "log"}}}}
    (folder / ROBOT_FUSION_FILE).write_text(json.dumps(doc))
    models = PerceptionModels.load(folder, "cpu")
    assert models.robot_inspection.fused_calibration == {"noisy-or": pooled}
    at_hard = models.at_level("hard")
    assert at_hard.robot_inspection.fused_calibration == {"noisy-or": hard}
    assert models.robot_inspection.fused_calibration == {"noisy-or": pooled}  # left as it was
    assert at_hard.robot_inspection.net is models.robot_inspection.net  # shared, not copied
    assert at_hard.inspection is models.inspection and at_hard.detector is models.detector
    assert models.at_level(DIFFICULTY_LEVELS["hard"]).robot_inspection.fused_calibration \
        == {"noisy-or": hard}
    assert models.at_level("clean") is models and models.at_level(None) is models
    assert (models.fused_calibration_of("hard"), models.fused_calibration_of("clean")) == (
        "hard", "pooled")
    views = [0.02, 0.9, 0.05]  # the same call, as sure as the level's map makes it
    evidence = log_odds(views, "noisy-or", train_prior=models.robot_inspection.rot_prior,
                        visibility=models.robot_inspection.visibility)
    got = {name: m.inspector(camera="robot", rule="noisy-or").verdict(views)
           for name, m in (("pooled", models), ("hard", at_hard))}
    assert got["pooled"].p_blemished == pytest.approx(1 / (1 + np.exp(-0.5 * evidence)))
    assert got["hard"].p_blemished == pytest.approx(
        1 / (1 + np.exp(-3.0 * np.log1p(evidence))))
    assert got["pooled"].prediction == got["hard"].prediction
    # a level's entry that is not a calibration: one line naming the file and the level
    for levels in ({"hard": {"noisy-or": {"low": -1.0, "high": 1.0}}}, [1],
                   {"hard": {"max": {"low": 1.0, "high": 1.0}}}):
        (folder / ROBOT_FUSION_FILE).write_text(json.dumps({**doc, "levels": levels}))
        with pytest.raises(ValueError, match=ROBOT_FUSION_FILE) as err:
            PerceptionModels.load(folder, "cpu")
        assert "\n" not in str(err.value)
        if isinstance(levels, dict):
            assert "level 'hard'" in str(err.value)


def test_the_log_form_lifts_weak_evidence_of_a_blemish_that_one_slope_hedges(caplog):
    """Good onions near the evidence of 5 clean views, blemished ones from a weak view to many
    strong ones, every call right (the robot at `hard`): one slope above 0 must temper the
    strong evidence and so hedges the weak; on log(1 + |E|) the slopes are better calibrated,
    with the same calls."""
    from onionsort.stages.inspection import fit_side_map

    rng = np.random.default_rng(4)
    good = -1.8 + rng.uniform(0, 0.4, 300)
    blemished = np.exp(rng.uniform(np.log(0.5), np.log(38), 300))
    evidence, y = np.r_[good, blemished], np.r_[np.zeros(300), np.ones(300)]
    assert fit_side_map(evidence, y) == fit_side_map(evidence, y, "slopes")

    def calibrated(form):  # 3 views under log-odds at prior 1/2: their logits sum to E
        c = fit_side_map(evidence, y, form)
        return np.array([fuse([1 / (1 + np.exp(-e / 3))] * 3, "log-odds", calibration=c)
                         for e in evidence])

    ece_slopes = expected_calibration_error(calibrated("slopes"), y)
    ece_log = expected_calibration_error(calibrated("log"), y)
    assert ece_log < ece_slopes / 2
    np.testing.assert_array_equal(calibrated("log") >= 0.5, evidence >= 0)
    with pytest.raises(ValueError, match="form must be one of"):
        fit_side_map(evidence, y, "isotonic")
    with caplog.at_level("WARNING"):  # every call right: each side's power runs to a bound
        assert fit_side_map(evidence, y, "powers")[3:] == pytest.approx((0.05, 0.05), rel=1e-3)
    assert "power below 0 runs to its bound" in caplog.text


def test_the_powers_form_recovers_a_steeper_fall_where_good_onions_gather():
    """Good onions' evidence gathers near the bound of 5 clean views, and a blemished onion
    whose rot no view shows sits a little above it (the robot at `hard`): classes drawn from
    a map with a power of 1.5 below 0 and 0.8 above. Under "powers" the fit finds that map's
    probabilities, calibrates better than "log" and keeps every call."""
    from onionsort.stages.inspection import fit_side_map

    rng = np.random.default_rng(5)
    evidence = np.r_[-1.8 + rng.gamma(1.0, 0.15, 6000), np.exp(rng.uniform(-1, 3.6, 6000))]
    truth = (1.6, 0.6, "powers", 1.5, 0.8)
    p_true = np.array([fuse([1 / (1 + np.exp(-e))], "log-odds", calibration=truth)
                       for e in evidence])
    y = (rng.uniform(size=evidence.size) < p_true).astype(float)
    low_power, high_power = fit_side_map(evidence, y, "powers")[3:]
    assert abs(low_power - 1.5) < 0.3 and abs(high_power - 0.8) < 0.3  # the truth's powers

    def calibrated(form):  # one view under log-odds at prior 1/2: its logit is E
        c = fit_side_map(evidence, y, form)
        return np.array([fuse([1 / (1 + np.exp(-e))], "log-odds", calibration=c)
                         for e in evidence])

    powers = calibrated("powers")
    assert np.max(np.abs(powers - p_true)) < 0.05  # "log" misses it by 0.16
    assert np.max(np.abs(calibrated("log") - p_true)) > 0.1
    assert expected_calibration_error(powers, y) < expected_calibration_error(
        calibrated("log"), y)
    np.testing.assert_array_equal(powers >= 0.5, evidence >= 0)


def test_a_powers_calibration_is_written_read_and_applied_at_its_level(tmp_path):
    from onionsort.stages.inspection import _write_fused_calibration, fit_fused_calibration
    from onionsort.stages.models import DEFAULT_MODELS, ROBOT_FUSION_FILE, PerceptionModels

    rng = np.random.default_rng(6)
    classes = np.r_[np.zeros(200, int), np.ones(200, int)]
    q = np.where(classes == 1, rng.uniform(0.6, 0.99, 400), rng.uniform(0.05, 0.4, 400))
    views, p = _views(q, classes)
    fitted = fit_fused_calibration(_classifier(), views, {"noisy-or": p}, "powers")
    entry = fitted["noisy-or"]
    assert entry["form"] == "powers" and entry["low_power"] > 0 and entry["high_power"] > 0
    assert entry["ece_after"] < entry["ece_before"]
    folder = tmp_path / "models"
    shutil.copytree(DEFAULT_MODELS, folder)
    _write_fused_calibration(folder, fitted, {"fitted_on": "a test"}, {"hard": fitted})
    models = PerceptionModels.load(folder, "cpu")
    want = (entry["low"], entry["high"], "powers", entry["low_power"], entry["high_power"])
    assert models.robot_inspection.fused_calibration == {"noisy-or": want}
    assert models.at_level("hard").robot_inspection.fused_calibration == {"noisy-or": want}
    # an entry of form "powers" without its powers: one line naming the file
    doc = json.loads((folder / ROBOT_FUSION_FILE).read_text())
    del doc["rules"]["noisy-or"]["high_power"]
    (folder / ROBOT_FUSION_FILE).write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=ROBOT_FUSION_FILE) as err:
        PerceptionModels.load(folder, "cpu")
    assert "\n" not in str(err.value)


def test_robot_fusion_refuses_bad_inputs_in_one_line(tmp_path, capsys):
    from onionsort.cli import main

    assert main(["train", "robot-fusion", "--data", str(tmp_path / "none"),
                 "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert err and "\n" not in err
    assert main(["train", "robot-fusion", "--data", str(tmp_path), "--views", "0",
                 "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert "views must be" in err and "\n" not in err
