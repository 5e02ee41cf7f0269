import dataclasses
import json

import numpy as np
import pytest

import irl
from irl.domains.onion_sorting import SORTING_TASK, factor_confusion
from irl.domains.task import TaskDescription
from state_abstraction.calibration import (
    FACTORS,
    calibrate,
    calibration_factors,
    load_calibration,
)

SIZES = {k: len(v) for k, v in FACTORS.items()}


def synthetic(rng, n_frames, confusions):
    """True factor values and predictions drawn from known confusion matrices."""
    true, pred = {}, {}
    for k, n in SIZES.items():
        t = rng.integers(n, size=n_frames)
        C = confusions[k]
        true[k] = t
        pred[k] = np.array([rng.choice(n, p=C[i]) for i in t])
    return true, pred


@pytest.fixture
def known():
    rng = np.random.default_rng(0)
    return {k: rng.dirichlet(np.ones(n) * 0.5, size=n) * 0.3 + np.eye(n) * 0.7
            for k, n in SIZES.items()}


def test_calibration_recovers_the_known_matrices(known):
    rng = np.random.default_rng(1)
    true, pred = synthetic(rng, 20_000, known)
    cal = calibrate(true, pred)
    for k in FACTORS:
        est = cal.factors[k].probabilities(smoothing=0.0)
        n_per_row = cal.factors[k].counts.sum(axis=1, keepdims=True)
        se = np.sqrt(known[k] * (1 - known[k]) / n_per_row)
        assert np.all(np.abs(est - known[k]) < 5 * se + 1e-12), k


def test_observation_model_fits_the_sorting_mdp_and_feeds_mmap_birl(known):
    rng = np.random.default_rng(2)
    cal = calibrate(*synthetic(rng, 3000, known))
    om = cal.observation_model(smoothing=1.0)
    assert om.probs.shape == (48, 5, 240)
    np.testing.assert_allclose(om.probs.sum(axis=2), 1.0)
    assert om.probs.min() > 0  # smoothing: nothing becomes impossible
    dom = irl.domains.onion_sorting()
    demos, _ = dom.sample(4, 15, occlusion=0.2, seed=0, observation_model=om)
    est = irl.MMAPBIRL(dom.mdp, om, beta=dom.beta, prior=dom.prior).fit(demos)
    assert np.isfinite(est.log_posterior_)


def test_state_error_rate_is_the_measured_joint_error():
    rng = np.random.default_rng(3)
    confusions = {k: factor_confusion(n, 0.1) for k, n in SIZES.items()}
    true, pred = synthetic(rng, 5000, confusions)
    cal = calibrate(true, pred)
    wrong = np.zeros(5000, bool)
    for k in ("onion", "end_effector", "prediction"):
        wrong |= true[k] != pred[k]
    assert cal.state_error_rate == pytest.approx(wrong.mean())
    assert cal.state_error_rate == pytest.approx(1 - 0.9**3, abs=0.03)


def test_save_load_round_trip_and_no_partial_file(tmp_path, known):
    cal = calibrate(*synthetic(np.random.default_rng(4), 500, known))
    path = cal.save(tmp_path / "calibration.json")
    assert not (tmp_path / "calibration.json.partial").exists()
    back = load_calibration(path)
    for k in FACTORS:
        np.testing.assert_array_equal(back.factors[k].counts, cal.factors[k].counts)
    np.testing.assert_allclose(back.observation_model().probs, cal.observation_model().probs)


def test_bad_files_and_inputs_are_clear_errors(tmp_path, known):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        load_calibration(tmp_path / "missing.json")
    (tmp_path / "x.json").write_text("not json")
    with pytest.raises(ValueError, match="not a calibration file"):
        load_calibration(tmp_path / "x.json")
    cal = calibrate(*synthetic(np.random.default_rng(5), 200, known))
    doc = json.loads(cal.save(tmp_path / "c.json").read_text())
    doc["n_states"] = 144
    (tmp_path / "other.json").write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=r"calibrated for an MDP with \(S, A\) = \(144, 5\)"):
        load_calibration(tmp_path / "other.json")
    true, pred = synthetic(np.random.default_rng(6), 10, known)
    pred["onion"] = pred["onion"][:5]
    with pytest.raises(ValueError, match="onion: true and predicted must be 1-D of equal length"):
        calibrate(true, pred)
    true, pred = synthetic(np.random.default_rng(6), 10, known)
    pred["action"] = pred["action"] + 5
    with pytest.raises(ValueError, match=r"action: predicted values must lie in \[0, 5\)"):
        calibrate(true, pred)
    del true["action"]
    with pytest.raises(ValueError, match="missing"):
        calibrate(true, pred)


# -- a made-up task: the calibration follows the task description --------------------------

TOY = TaskDescription("toy-room", {"light": ("off", "on"), "door": ("closed", "open", "ajar")},
                      action_names=("wait", "toggle"), feature_names=("lit",))
TOY_SIZES = {k: len(v) for k, v in calibration_factors(TOY).items()}


def toy_data(seed, n_frames=4000, error=0.15):
    rng = np.random.default_rng(seed)
    true, pred = {}, {}
    for k, n in TOY_SIZES.items():
        C = factor_confusion(n, error)
        true[k] = rng.integers(n, size=n_frames)
        pred[k] = np.array([rng.choice(n, p=C[i]) for i in true[k]])
    return true, pred


def test_calibration_factors_of_a_task():
    assert calibration_factors(TOY) == {"light": ["off", "on"],
                                        "door": ["closed", "open", "ajar"],
                                        "action": ["wait", "toggle"]}
    assert calibration_factors(SORTING_TASK) == FACTORS
    bad = TaskDescription("bad", {"action": ("a", "b")}, action_names=("x",),
                          feature_names=("f",))
    with pytest.raises(ValueError, match="state factor named 'action'"):
        calibration_factors(bad)


def test_a_calibration_of_a_two_factor_task():
    true, pred = toy_data(7)
    cal = calibrate(true, pred, task=TOY)
    assert (cal.task, cal.task_name, cal.n_states, cal.n_actions) == (TOY, "toy-room", 6, 2)
    assert list(cal.factors) == ["light", "door", "action"]
    assert cal.joint_state.counts.shape == (6, 6)
    s_true = [TOY.encode({"light": int(a), "door": int(b)})
              for a, b in zip(true["light"], true["door"], strict=True)]
    s_pred = [TOY.encode({"light": int(a), "door": int(b)})
              for a, b in zip(pred["light"], pred["door"], strict=True)]
    expected = np.zeros((6, 6), int)
    np.add.at(expected, (s_true, s_pred), 1)
    np.testing.assert_array_equal(cal.joint_state.counts, expected)
    assert cal.state_error_rate == pytest.approx(np.mean(np.array(s_true) != np.array(s_pred)))
    om = cal.observation_model(smoothing=1.0)
    assert om.probs.shape == (6, 2, TOY.n_pairs)
    np.testing.assert_allclose(om.probs.sum(axis=2), 1.0)
    # P(o | s, a) of a pair o = TOY.pair(s', a') is the product of the factors' confusions
    C = {k: cal.factors[k].probabilities(1.0) for k in TOY_SIZES}
    s, a, s2, a2 = 4, 1, 3, 0
    f, f2 = TOY.decode(s), TOY.decode(s2)
    want = C["light"][f["light"], f2["light"]] * C["door"][f["door"], f2["door"]] \
        * C["action"][a, a2]
    assert om.probs[s, a, TOY.pair(s2, a2)] == pytest.approx(want)


def test_a_two_factor_calibration_saves_and_loads_for_its_task(tmp_path):
    cal = calibrate(*toy_data(8, 500), task=TOY)
    path = cal.save(tmp_path / "toy.json")
    doc = json.loads(path.read_text())
    assert (doc["n_states"], doc["n_actions"]) == (6, 2)
    back = load_calibration(path, task=TOY)
    assert back.task == TOY
    np.testing.assert_allclose(back.observation_model().probs, cal.observation_model().probs)
    with pytest.raises(ValueError, match=r"\(S, A\) = \(6, 2\), not the onion-sorting MDP's "
                                         r"\(48, 5\)"):
        load_calibration(path)
    renamed = TaskDescription("toy-room", {"light": ("dark", "bright"),
                                           "door": ("closed", "open", "ajar")},
                              action_names=("wait", "toggle"), feature_names=("lit",))
    with pytest.raises(ValueError, match="the values of factor 'light' must be"):
        load_calibration(path, task=renamed)
    missing = {k: v for k, v in toy_data(9, 10)[0].items() if k != "door"}
    with pytest.raises(ValueError, match=r"\['light', 'door', 'action'\]; missing \['door'\]"):
        calibrate(missing, missing, task=TOY)


def test_the_shipped_calibration_still_loads():
    from pathlib import Path

    import state_abstraction

    shipped = Path(state_abstraction.__file__).parents[1] / "onionsort/models/calibration.json"
    if not shipped.exists():
        pytest.skip("no shipped calibration")
    cal = load_calibration(shipped)
    assert cal.task == SORTING_TASK
    assert cal.observation_model().probs.shape == (48, 5, 240)


def test_the_independence_check_tells_errors_that_come_together_from_independent_ones():
    """Two factors wrong on 10% of 200 steps each: on the same steps, on disjoint steps, or
    independently drawn; the action wrong on the first 20 steps."""
    n = 200
    true = {"light": np.zeros(n, int), "door": np.zeros(n, int), "action": np.zeros(n, int)}
    wrong = {"together": (np.arange(20), np.arange(20)),
             "apart": (np.arange(20), np.arange(20, 40))}
    for case, (light, door) in wrong.items():
        pred = {k: v.copy() for k, v in true.items()}
        pred["light"][light] = 1
        pred["door"][door] = 2
        pred["action"][:20] = 1
        cal = calibrate(true, pred, task=TOY)
        # what the factored model implies: one minus the product of the accuracies, 0.9 x 0.9
        assert cal.independent_state_error_rate == pytest.approx(0.19)
        assert cal.state_error_rate == pytest.approx(0.10 if case == "together" else 0.20)
        # the action errs on the steps the state does (on 20 of them)
        assert cal.pair_error_rate == pytest.approx(cal.state_error_rate)
        assert cal.independent_pair_error_rate == pytest.approx(
            1 - (1 - cal.state_error_rate) * 0.9)
    cal = calibrate(*toy_data(3, 20000), task=TOY)  # independent errors: the two agree
    assert cal.independent_state_error_rate == pytest.approx(cal.state_error_rate, abs=0.01)
    assert cal.independent_pair_error_rate == pytest.approx(cal.pair_error_rate, abs=0.01)


def measured_session(true_class, read_class, occluded=None):
    """One session as ``onionsort.stages.calibrate._measure_session`` reports it, its
    prediction factor only (class names; the other factors unread)."""
    idx = {v: i for i, v in enumerate(FACTORS["prediction"])}
    n = len(true_class)
    return {"true": {"prediction": [idx[v] for v in true_class]},
            "pred": {"prediction": [idx[v] for v in read_class]},
            "called_occluded": occluded or [False] * n}


def test_a_session_whose_class_reads_are_mostly_backwards_counts_as_swapped():
    from onionsort.stages.calibrate import session_swaps

    sessions = [
        measured_session(["good", "bad", "bad", "good"], ["bad", "good", "good", "good"]),
        measured_session(["good", "bad", "bad", "good"], ["good", "good", "bad", "good"]),
        # two of four reads backwards is not more than half; the occluded read not counted
        measured_session(["good", "bad", "bad", "good"], ["bad", "bad", "good", "good"]),
        measured_session(["good", "bad", "unknown"], ["bad", "good", "unknown"],
                         occluded=[False, True, False]),  # one read: too few to tell
    ]
    swaps = session_swaps(sessions)
    assert (swaps["sessions"], swaps["swapped"]) == (3, 1)
    assert swaps["reads"] == [4, 4, 4, 1] and swaps["swapped_reads"] == [3, 1, 2, 1]
    good, bad, unknown = range(3)
    counts = np.array(swaps["prediction_counts"])
    # the swapped session's reads swapped back: its one wrong read stays wrong
    assert counts[good, good] == 1 + 2 + 1 + 0 and counts[good, bad] == 1 + 0 + 1 + 1
    assert counts[bad, bad] == 2 + 1 + 1 and counts[bad, good] == 0 + 1 + 1
    assert counts[unknown, unknown] == 1 and counts.sum() == 4 + 4 + 4 + 2


def test_the_session_swaps_save_load_and_give_the_learners_their_model(tmp_path, known):
    rng = np.random.default_rng(3)
    cal = calibrate(*synthetic(rng, 3000, known))
    with pytest.raises(ValueError, match="calibrate again"):
        cal.session_swap()
    assert cal.session_swap_rate is None
    within = [[30, 2, 1], [3, 28, 2], [0, 0, 40]]
    cal = dataclasses.replace(cal, session_swaps={"sessions": 25, "swapped": 2,
                                                  "prediction_counts": within})
    assert cal.session_swap_rate == pytest.approx(3 / 27)
    back = load_calibration(cal.save(tmp_path / "calibration.json"))
    assert back.session_swaps == cal.session_swaps
    swap = back.session_swap()
    assert swap.rate == pytest.approx(3 / 27) and swap.n_observations == 240
    plain, inside = back.observation_model(), back.observation_model(within_sessions=True)
    assert not np.allclose(plain.probs, inside.probs)  # the prediction factor alone differs
    other = dataclasses.replace(back, factors={**back.factors, "prediction": type(
        back.factors["prediction"])(np.array(within), back.factors["prediction"].labels)})
    np.testing.assert_allclose(inside.probs, other.observation_model().probs)
    doc = json.loads((tmp_path / "calibration.json").read_text())
    doc["session_swaps"]["swapped"] = 30
    (tmp_path / "bad.json").write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=r"bad\.json: session_swaps must hold") as info:
        load_calibration(tmp_path / "bad.json")
    assert "\n" not in str(info.value)
