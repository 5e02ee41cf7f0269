import json

import numpy as np
import pytest

import irl
from irl.domains.onion_sorting import factor_confusion
from state_abstraction.calibration import FACTORS, calibrate, load_calibration

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
