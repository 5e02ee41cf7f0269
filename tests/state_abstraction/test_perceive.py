"""Perception of sessions: the prediction tracker, perceived demonstrations, the commands."""

import json

import numpy as np
import pytest
import torch

from irl.domains.onion_sorting import Location, Prediction
from onionsort.cli import main
from onionsort.stages.models import PerceptionModels
from onionsort.stages.perceive import perceive_session
from perception import Detector, DetectorConfig, DetectorNet
from perception.inspection import InspectionClassifier, InspectionNet, InspectionNetConfig
from recordings import open_session
from state_abstraction.classifier import HEADS, ClassifierConfig, StateClassifier
from state_abstraction.perceive import track_predictions

C, H, F, B = Location.CONVEYOR, Location.HOVER, Location.FACE, Location.BIN
G, X, U = Prediction.GOOD, Prediction.BAD, Prediction.UNKNOWN


def test_predictions_come_from_inspection_and_reset_on_a_new_onion():
    # claim (gate up), pick, inspect (blemished), bin, claim, pick, inspect (good), back on belt
    onion = [C, H, F, B, C, H, F, C]
    waiting = [1, 0, 0, 0, 1, 0, 0, 0]
    occluded = [0] * 8
    seen = [[], [], [0.9], [], [], [], [0.2], []]
    predictions, p_bad = track_predictions(onion, waiting, occluded, seen)
    assert predictions == [U, U, X, X, U, U, G, G]
    assert p_bad == [None, None, 0.9, 0.9, None, None, 0.2, 0.2]


def test_views_of_a_later_frame_count_from_the_next_step_and_views_are_fused():
    # the inspection step's later frames show the onion coming up: from the next step on
    onion = [C, H, F, B]
    at_rest = [[], [], [0.7], []]
    later = [[], [0.8], [], []]
    predictions, p_bad = track_predictions(onion, [1, 0, 0, 0], [0] * 4, at_rest, later,
                                           fuse=max)
    assert predictions == [U, U, X, X] and p_bad == [None, None, 0.8, 0.8]
    # a view seen while the onion is still at the gate is forgotten when it is picked
    predictions, _ = track_predictions([C, H], [1, 0], [0, 0], [[0.9], []], None)
    assert predictions == [X, U]


def test_an_inspection_seen_during_an_occluded_step_still_counts():
    onion = [C, H, F, B]
    predictions, _ = track_predictions(onion, [1, 0, 0, 0], [0, 0, 1, 0], [[], [], [0.7], []])
    assert predictions == [U, U, X, X]
    with pytest.raises(ValueError, match="equal lengths"):
        track_predictions(onion, [1], [0], [[]])


@pytest.fixture(scope="module")
def random_models(tmp_path_factory):
    """Untrained models: their calls are arbitrary, which is what these tests need."""
    folder = tmp_path_factory.mktemp("models")
    torch.manual_seed(0)
    StateClassifier(ClassifierConfig(width=64, height=48, channels=4)).save(
        folder / "state_classifier.pt")
    Detector(DetectorNet(DetectorConfig(width=128, height=96, channels=4))).save(
        folder / "detector.pt")
    InspectionClassifier(InspectionNet(InspectionNetConfig(width=4))).save(
        folder / "inspection_classifier.pt")
    return folder


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    out = tmp_path_factory.mktemp("rec")
    assert main(["record", "--sessions", "1", "--steps-per-session", "8", "--occlusion", "0.5",
                 "--seed", "2", "--out", str(out)]) == 0
    return next(out.glob("*.mcap"))


class ScriptedClassifier(StateClassifier):
    """Calls every third step occluded; random estimates otherwise."""

    def predict(self, x, batch_size=64):
        rng = np.random.default_rng(len(x))
        probs = {k: rng.dirichlet(np.ones(n), len(x)) for k, n in HEADS.items()}
        probs["occluded"] = np.array([[0.1, 0.9] if t % 3 == 1 else [0.95, 0.05]
                                      for t in range(len(x))])
        return probs


def test_perceived_demonstration_has_none_exactly_where_the_classifier_said_occluded(
        random_models, session, tmp_path):
    path = tmp_path / session.name
    path.write_bytes(session.read_bytes())
    with pytest.raises(ValueError, match="no perception topics"):
        open_session(path).perceived_demonstration()
    models = PerceptionModels.load(random_models)
    models.classifier = ScriptedClassifier(models.classifier.config)
    steps = perceive_session(models, path).steps
    called = [s.occluded for s in steps]
    assert called == [t % 3 == 1 for t in range(8)]
    demo = open_session(path).perceived_demonstration()
    assert [o is None for o in demo.observations] == called
    for s, o in zip(steps, demo.observations, strict=True):
        assert o is None or o == s.state * 5 + s.action
    # the ground truth is untouched and the file still passes a CRC-validating read
    again = open_session(path)
    assert again.steps == open_session(session).steps
    assert again.perception_models["detector_sha256"]
    with pytest.raises(FileExistsError, match="already holds perception"):
        perceive_session(models, path)
    assert perceive_session(models, path, replace=True).n_steps == len(steps)


@pytest.fixture(scope="module")
def small_data(tmp_path_factory):
    """A dataset of 3 sessions of 12 frames, no robot views."""
    data = tmp_path_factory.mktemp("small") / "data"
    assert main(["dataset", "--frames", "36", "--robot-onions", "0",
                 "--steps-per-session", "4", "--seed", "4", "--out", str(data)]) == 0
    return data


def test_calibrate_and_eval_perception_commands(random_models, small_data, tmp_path, capsys):
    data = small_data
    out = tmp_path / "cal"
    assert main(["calibrate", "--data", str(data), "--models", str(random_models),
                 "--out", str(out)]) == 0
    doc = json.loads((out / "calibration.json").read_text())
    assert set(doc["factors"]) == {"onion", "end_effector", "prediction", "action"}
    # the dataset by name and seed, not by a path of this machine
    assert doc["data"] == {"name": "data", "seed": 4, "frames": 36, "difficulty": "clean"}
    probs = np.load(out / "observation_model.npz")["probs"]
    assert probs.shape == (48, 5, 240)
    np.testing.assert_allclose(probs.sum(axis=2), 1.0)
    assert (out / "confusion.png").stat().st_size > 0
    assert "sessions read backwards" in capsys.readouterr().out
    assert main(["eval-perception", "--data", str(data), "--models", str(random_models),
                 "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert {"map50", "map50_95", "accuracy", "occlusion_recall"} <= set(result)
    for view in ("camera", "inspection", "all"):  # as measured per class and with any class
        assert {"map50", "map50_any_class"} <= set(result["map_by_view"][view])
    assert set(result["accuracy"]) == {"onion", "end_effector", "prediction", "action"}
    assert "prediction_after_first_inspection" in result
    assert {"sessions", "swapped"} <= set(result["session_swaps"])
    assert "camera_shift" not in result


def test_eval_perception_through_other_cameras_only_when_asked(random_models, small_data,
                                                                capsys, monkeypatch):
    from perception.camera_shift import CameraShift

    data = small_data
    shifted = []  # (camera, image shape) of each image a camera changed
    apply = CameraShift.apply

    def spy(self, image):
        shifted.append((self, image.shape))
        return apply(self, image)

    monkeypatch.setattr(CameraShift, "apply", spy)
    argv = ["eval-perception", "--data", str(data), "--split", "all", "--models",
            str(random_models)]
    capsys.readouterr()
    assert main([*argv, "--json"]) == 0
    plain = json.loads(capsys.readouterr().out)
    assert not shifted  # never applied unless asked
    assert main([*argv, "--json", "--camera-shift", "11"]) == 0
    result = json.loads(capsys.readouterr().out)
    shift = result["camera_shift"]
    assert shift["seeds"] == [11] and shift["one_camera"] is False
    assert shift["sessions"] == plain["session_swaps"]["sessions"]
    # the unchanged figures are those of a run without cameras; the changed ones are measured
    assert {k: v for k, v in result.items() if k != "camera_shift"} == plain
    (one,) = shift["shifted"]
    assert one.keys() == plain.keys()
    cameras = {camera for camera, _ in shifted}
    assert len(cameras) == 3  # one per session (3 sessions of 12 frames), main and close views
    assert {shape for _, shape in shifted} == {(240, 320, 3), (120, 160, 3)}
    # reproducible from its seed: the same cameras and figures again
    shifted.clear()
    assert main([*argv, "--json", "--camera-shift", "11"]) == 0
    assert json.loads(capsys.readouterr().out) == result
    assert {camera for camera, _ in shifted} == cameras
    # one seed: its mean and its worst are its figure
    for name, f in shift["figures"].items():
        assert f["changed"] == [f["mean"]] == [f["worst"]], name
    from onionsort.commands.eval_perception import _print_shift

    _print_shift(shift)
    text = capsys.readouterr().out
    assert "through other cameras (seed 11): each session and robot line-up a camera" in text
    assert "unchanged      11    mean  mean drop  worst drop" in text
    assert f"sessions read backwards (of {shift['sessions']})" in text
    # the fused calls' figures include the fused probability's calibration (ECE)
    from onionsort.stages.calibrate import perception_figures as figures

    fused = {"accuracy": 0.9, "precision": 1.0, "recall": 0.8, "ece": 0.07}
    level = {"found": 1.0, "rot_accuracy": 0.9, "view_accuracy": 0.8,
             "fused": {"noisy-or": fused}}
    named = figures({**result, "inspection_classifier": {"levels": {"clean": {"robot": level}}}})
    assert named["inspection clean robot: fused by noisy-or, ECE"] == 0.07


def test_eval_perception_through_several_cameras_is_reproducible(random_models, small_data,
                                                                 capsys, monkeypatch):
    """``--camera-shift 11,12,13``: each seed's figures are those it gives alone, the mean and
    the worst are over the seeds, and the whole is the same from the same seeds; with
    ``--one-camera`` every session goes through the seed's one camera."""
    argv = ["eval-perception", "--data", str(small_data), "--split", "all", "--models",
            str(random_models), "--no-inspection", "--json"]
    capsys.readouterr()
    assert main([*argv, "--camera-shift", "11,12,13"]) == 0
    several = json.loads(capsys.readouterr().out)
    assert main([*argv, "--camera-shift", "11,12,13"]) == 0
    assert json.loads(capsys.readouterr().out) == several
    assert main([*argv, "--camera-shift", "12"]) == 0
    alone = json.loads(capsys.readouterr().out)["camera_shift"]
    shift = several["camera_shift"]
    assert shift["seeds"] == [11, 12, 13]
    assert shift["shifted"][1] == alone["shifted"][0]
    for name, f in shift["figures"].items():
        assert f["changed"][1] == alone["figures"][name]["changed"][0]
        if f["unchanged"] is None or None in f["changed"]:
            continue
        worse_high = "ECE" in name or name == "sessions read backwards"
        assert f["mean"] == pytest.approx(np.mean(f["changed"]))
        assert f["worst"] == (max if worse_high else min)(f["changed"])
        sign = -1 if worse_high else 1
        assert f["worst_drop"] == pytest.approx(sign * (f["unchanged"] - f["worst"]))
        assert f["worst_drop"] >= f["mean_drop"] - 1e-12
    from onionsort.commands.eval_perception import _print_shift

    _print_shift(shift)
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("through other cameras (seeds 11, 12, 13)")
    assert "unchanged      11      12      13    mean  mean drop  worst drop" in lines[1]
    row = next(line for line in lines if "state: onion" in line).split()
    f = shift["figures"]["state: onion"]
    assert [float(x) for x in row[2:9]] == pytest.approx(
        [f["unchanged"], *f["changed"], f["mean"], f["mean_drop"], f["worst_drop"]], abs=6e-4)
    # one camera per seed for every session and line-up
    from onionsort.stages.cameras import SessionCameras
    from perception.camera_shift import CameraShift

    cameras = SessionCameras(12, one_camera=True)
    assert cameras.camera({"session": 0}) == cameras.camera(
        {"source": "robot", "lineup": 4}) == CameraShift.draw(12)
    assert SessionCameras(11).camera({"session": 0}) != SessionCameras(13).camera(
        {"session": 0})
    used = set()
    apply = CameraShift.apply

    def spy(self, image):
        used.add(self)
        return apply(self, image)

    monkeypatch.setattr(CameraShift, "apply", spy)
    assert main([*argv, "--camera-shift", "12", "--one-camera"]) == 0
    one = json.loads(capsys.readouterr().out)["camera_shift"]
    assert one["one_camera"] is True and one["seeds"] == [12]
    assert used == {CameraShift.draw(12)}


def test_eval_perception_through_other_cameras_names_the_plots_it_wrote(tmp_path, capsys,
                                                                        monkeypatch):
    """``--camera-shift`` with ``--plots``: the table, then the plots written (as without)."""
    import onionsort.stages
    from onionsort.stages.calibrate import shift_summary

    figures = {"map_by_view": {"all": {"map50": 0.8}}, "accuracy": {"onion": 1.0},
               "prediction_after_first_inspection": None, "occlusion_recall": 1.0,
               "occlusion_precision": 1.0, "session_swaps": {"sessions": 2, "swapped": 0}}
    plot = tmp_path / "pr" / "pr.png"
    monkeypatch.setattr(onionsort.stages, "eval_perception", lambda config: {
        **figures, "plots": [str(plot)], "camera_shift": {
            "seeds": [3], "one_camera": False, "sessions": 2, "shifted": [figures],
            "figures": shift_summary(figures, [figures])}})
    assert main(["eval-perception", "--data", str(tmp_path), "--camera-shift", "3", "--plots",
                 str(tmp_path / "pr")]) == 0
    out = capsys.readouterr().out
    assert "through other cameras (seed 3)" in out and f"wrote {plot}" in out


def test_shift_summary_takes_the_worst_seed_in_the_bad_direction():
    """A figure's worst seed is its lowest, an ECE's and the sessions read backwards' their
    highest; a drop is how much worse than unchanged; None stays None."""
    from onionsort.stages.calibrate import shift_summary

    def result(onion, ece, swapped, prediction=0.9):
        level = {"found": 1.0, "rot_accuracy": 0.9, "view_accuracy": 0.8,
                 "fused": {"noisy-or": {"accuracy": 0.9, "precision": 1.0, "recall": 0.8,
                                        "ece": ece}}}
        return {"map_by_view": {"all": {"map50": 0.8}}, "accuracy": {"onion": onion},
                "prediction_after_first_inspection": prediction, "occlusion_recall": 1.0,
                "occlusion_precision": 1.0, "session_swaps": {"sessions": 4,
                                                              "swapped": swapped},
                "inspection_classifier": {"levels": {"hard": {"robot": level}}}}

    out = shift_summary(result(1.0, 0.05, 0), [result(0.9, 0.10, 1, None),
                                               result(0.7, 0.02, 0, 0.8)])
    onion = out["state: onion"]
    assert onion["changed"] == [0.9, 0.7] and onion["worst"] == 0.7
    assert onion["mean"] == pytest.approx(0.8) and onion["mean_drop"] == pytest.approx(0.2)
    assert onion["worst_drop"] == pytest.approx(0.3)
    ece = out["inspection hard robot: fused by noisy-or, ECE"]
    assert ece["worst"] == 0.10 and ece["worst_drop"] == pytest.approx(0.05)
    assert ece["mean_drop"] == pytest.approx(0.01)
    swaps = out["sessions read backwards"]
    assert swaps == {"unchanged": 0, "changed": [1, 0], "mean": 0.5, "worst": 1,
                     "mean_drop": 0.5, "worst_drop": 1.0}
    none = shift_summary(result(1.0, 0.05, 0), [result(1.0, 0.05, 0)])["sessions read backwards"]
    assert str(none["mean_drop"]) == str(none["worst_drop"]) == "0.0"  # not -0.0
    prediction = out["state: prediction after the first inspection"]
    assert prediction["changed"] == [None, 0.8]
    assert prediction["mean"] is prediction["worst"] is prediction["worst_drop"] is None


def test_missing_models_name_the_training_command(random_models, tmp_path):
    with pytest.raises(FileNotFoundError, match="onionsort train state-classifier"):
        PerceptionModels.load(tmp_path)
    for name in ("state_classifier.pt", "detector.pt"):
        (tmp_path / name).write_bytes((random_models / name).read_bytes())
    with pytest.raises(FileNotFoundError, match="onionsort train inspection"):
        PerceptionModels.load(tmp_path)


def test_learn_from_perceived_sessions_and_its_refusals(random_models, session, tmp_path, capsys):
    data = tmp_path / "data"
    assert main(["dataset", "--frames", "36", "--robot-onions", "0",
                 "--steps-per-session", "4", "--seed", "6",
                 "--out", str(data)]) == 0
    assert main(["calibrate", "--data", str(data), "--models", str(random_models),
                 "--out", str(tmp_path / "cal")]) == 0
    calibration = tmp_path / "cal" / "calibration.json"
    raw = tmp_path / "raw.mcap"
    raw.write_bytes(session.read_bytes())
    capsys.readouterr()
    assert main(["learn", str(raw), "--observation-model", str(calibration),
                 "--out", str(tmp_path / "bad")]) == 2
    assert "has no perception topics; run `onionsort perceive" in capsys.readouterr().err
    models = PerceptionModels.load(random_models)
    models.classifier = ScriptedClassifier(models.classifier.config)
    perceived = tmp_path / "perceived.mcap"
    perceived.write_bytes(session.read_bytes())
    perceive_session(models, perceived)
    out = tmp_path / "learn"
    assert main(["learn", str(perceived), "--method", "mmap-birl", "--observation-model",
                 str(calibration), "--out", str(out)]) == 0
    model = json.loads((out / "model.json").read_text())
    assert len(model["policy"]) == 48 and len(model["theta"]) == 6
    assert model["n_occluded"] == 3  # steps 1, 4, 7 of 8
    assert (out / "learn.rrd").stat().st_size > 0 and (out / "learning_curve.png").exists()
    other = json.loads(calibration.read_text())
    other["n_states"] = 12
    wrong = tmp_path / "other.json"
    wrong.write_text(json.dumps(other))
    assert main(["learn", str(perceived), "--observation-model", str(wrong),
                 "--out", str(tmp_path / "bad2")]) == 2
    assert "not the onion-sorting MDP" in capsys.readouterr().err


def test_prediction_after_first_inspection_leaves_out_the_steps_before_it(monkeypatch):
    from types import SimpleNamespace as NS

    import recordings.labels.dataset
    from onionsort.stages.calibrate import measure_perception

    # one session: the first two steps precede any inspection and are wrong, the rest are right
    truth = [1, 1, 0, 0, 0]
    seen_pred = [2, 2, 0, 0, 1]
    inspected = [None, None, 0, None, None]
    steps = [NS(colors=None, depths=None, views=None,
                record={"occluded": False, "onion": 0, "end_effector": 0, "prediction": t,
                        "action": 0}) for t in truth]
    perceived = [NS(occluded=False, onion=0, end_effector=0, prediction=p, action=0,
                    inspected=i) for p, i in zip(seen_pred, inspected, strict=True)]
    monkeypatch.setattr(recordings.labels.dataset, "read_steps", lambda *a, **k: [steps])
    models = NS(frames_per_step=3, perceive=lambda _: perceived,
                describe=lambda: {"folder": "fake"})
    _, metrics = measure_perception(models, "unused", "all")
    assert metrics["accuracy"]["prediction"] == 2 / 5
    assert metrics["prediction_after_first_inspection"] == 2 / 3
