"""The state classifier: training on in-memory steps, optional depth, depth dropout, the shipped
model with and without depth, and the import rules of the perception packages."""

import json
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pytest
import torch

import state_abstraction.classifier as classifier_module
from irl.domains.onion_sorting import Location, Prediction
from onionsort.cli import main
from recordings.labels.dataset import DatasetStep, read_steps
from state_abstraction.classifier import (
    ClassifierConfig,
    LabelledStep,
    StateClassifier,
    drop_depth,
    evaluate_steps,
    step_input,
    steps_to_tensors,
    train_classifier,
)
from state_abstraction.perceive import perceive_steps

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = ROOT / "onionsort" / "models" / "state_classifier.pt"
TINY = ClassifierConfig(width=32, height=24, channels=4, epochs=6, batch_size=8, lr=1e-2)


@dataclass(frozen=True)
class Step:
    """A synthetic step: the onion's location is where a bright square is, the hand's where a
    dark one is; an occluded step is mostly grey."""

    colors: list
    depths: list
    record: dict


def synthetic_steps(n: int, seed: int) -> list[Step]:
    rng = np.random.default_rng(seed)
    corners = [(0, 0), (0, 32), (24, 0), (24, 32)]
    steps = []
    for _ in range(n):
        onion, hand = (int(v) for v in rng.integers(0, 4, 2))
        occluded = bool(rng.random() < 0.25)
        img = rng.integers(0, 40, (48, 64, 3), dtype=np.uint8)
        (y, x), (v, u) = corners[onion], corners[hand]
        img[y:y + 24, x:x + 32, 0] = 255
        img[v + 6:v + 18, u + 8:u + 24, 2] = 200
        depth = np.full((48, 64), 1.5, np.float32)
        depth[v:v + 24, u:u + 32] = 1.0
        if occluded:
            img[:, 8:56] = 128
        steps.append(Step([img] * 3, [depth] * 3, {
            "onion": onion, "end_effector": hand, "action": int(rng.integers(0, 5)),
            "prediction": int(Prediction.UNKNOWN), "occluded": occluded}))
    return steps


def test_training_on_in_memory_steps_writes_a_checkpoint_and_uses_depth_dropout(
        tmp_path, monkeypatch):
    torch.set_num_threads(2)
    rates = []
    real = classifier_module.drop_depth

    def recording_drop_depth(x, p, generator=None):
        rates.append(p)
        return real(x, p, generator)

    monkeypatch.setattr(classifier_module, "drop_depth", recording_drop_depth)
    config = replace(TINY, depth_dropout=0.25)
    metrics = train_classifier(synthetic_steps(48, 0), synthetic_steps(16, 1),
                               synthetic_steps(16, 2), config, tmp_path / "run")
    losses = [h["train_loss"] for h in metrics["history"]]
    assert losses[-1] < losses[0]
    assert set(metrics["test"]) == {"accuracy_onion", "accuracy_end_effector",
                                    "accuracy_action", "accuracy_waiting",
                                    "occlusion_recall", "occlusion_precision"}
    assert set(metrics["test_without_depth"]) == set(metrics["test"])
    assert "accuracy_onion_without_depth" in metrics["history"][0]  # val picks on both modes
    assert 0.25 in rates  # the training batches dropped depth at the configured rate
    saved = json.loads((tmp_path / "run" / "state_classifier_metrics.json").read_text())
    assert saved["config"]["depth_dropout"] == 0.25 and saved["n_steps"]["train"] == 48
    model = StateClassifier.load(tmp_path / "run" / "state_classifier.pt")
    assert model.config == config
    x, y = steps_to_tensors(synthetic_steps(5, 3), config)
    np.testing.assert_allclose(model.predict(x)["onion"].sum(axis=1), 1.0, rtol=1e-5)
    assert x.shape == (5, 12, 24, 32) and x.dtype == torch.float16
    assert set(y) == {"onion", "end_effector", "action", "waiting", "occluded"}
    with pytest.raises(ValueError, match="steps must hold at least one step"):
        train_classifier([], synthetic_steps(4, 1), [], config, tmp_path / "empty")


def test_dataset_steps_satisfy_the_protocol():
    step = DatasetStep([np.zeros((4, 4, 3), np.uint8)] * 3, [np.zeros((4, 4))] * 3, None,
                       {"onion": 0, "end_effector": 0, "action": 0, "prediction": 2,
                        "occluded": False})
    assert isinstance(step, LabelledStep)
    x, y = steps_to_tensors([step], ClassifierConfig(width=8, height=6))
    assert x.shape == (1, 12, 6, 8) and y["waiting"].item() == 1


def test_a_step_without_depth_reads_as_zero_depth():
    config = ClassifierConfig(width=64, height=48, frames=3)
    rng = np.random.default_rng(0)
    colors = [rng.integers(0, 255, (240, 320, 3), dtype=np.uint8) for _ in range(3)]
    zeros = [np.zeros((240, 320), np.float32)] * 3
    expected = step_input(colors, zeros, config)
    np.testing.assert_array_equal(step_input(colors, None, config), expected)
    np.testing.assert_array_equal(step_input(colors, [None] * 3, config), expected)
    with_depth = step_input(colors, [np.ones((240, 320), np.float32)] * 3, config)
    np.testing.assert_array_equal(with_depth[[0, 1, 2, 4, 5, 6, 8, 9, 10]],
                                  expected[[0, 1, 2, 4, 5, 6, 8, 9, 10]])
    assert np.all(expected[[3, 7, 11]] == 0) and np.all(with_depth[[3, 7, 11]] > 0)
    with pytest.raises(ValueError, match="a step must have 3 frames"):
        step_input(colors[:2], None, config)


def test_depth_dropout_zeroes_whole_steps_at_the_configured_rate():
    x = torch.rand(4000, 12, 3, 4) + 0.1
    dropped_x, dropped = drop_depth(x, 0.3, torch.Generator().manual_seed(0))
    # binomial(4000, 0.3): standard deviation 0.007
    assert abs(dropped.float().mean().item() - 0.3) < 0.03
    depth, colour = [3, 7, 11], [c for c in range(12) if c not in (3, 7, 11)]
    assert torch.all(dropped_x[dropped][:, depth] == 0)
    assert torch.equal(dropped_x[~dropped], x[~dropped])
    assert torch.equal(dropped_x[:, colour], x[:, colour])
    assert torch.all(x[:, depth] > 0)  # the input is not changed
    again, same = drop_depth(x, 0.3, torch.Generator().manual_seed(0))
    assert torch.equal(same, dropped) and torch.equal(again, dropped_x)
    assert not drop_depth(x, 0.0)[1].any() and drop_depth(x, 1.0)[1].all()
    with pytest.raises(ValueError, match="p must be in"):
        drop_depth(x, 1.5)
    with pytest.raises(ValueError, match="depth_dropout must be in"):
        ClassifierConfig(depth_dropout=-0.1)


@pytest.fixture(scope="module")
def fresh_dataset(tmp_path_factory):
    """Small sessions rendered now, with a seed no model was trained, tuned or reported on
    (datasets of seeds 0, 1 and 2 made and measured the shipped model)."""
    out = tmp_path_factory.mktemp("fresh") / "data"
    assert main(["dataset", "--frames", "150", "--robot-onions", "0",
                 "--steps-per-session", "10", "--seed", "11", "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def fresh_steps(fresh_dataset):
    return [step for session in read_steps(fresh_dataset, "all", 3) for step in session]


def test_the_train_stage_reads_the_dataset_and_trains_through_the_cli(fresh_dataset, tmp_path,
                                                                     capsys):
    out = tmp_path / "run"
    assert main(["train", "state-classifier", "--data", str(fresh_dataset), "--out", str(out),
                 "--epochs", "1", "--depth-dropout", "0.3"]) == 0
    printed = capsys.readouterr().out
    assert "state classifier, test split: accuracy_onion" in printed
    assert "state classifier, test split without depth: accuracy_onion" in printed
    assert StateClassifier.load(out / "state_classifier.pt").config.depth_dropout == 0.3
    assert main(["train", "state-classifier", "--data", str(tmp_path), "--out", str(out)]) == 2
    assert "is not a dataset folder" in capsys.readouterr().err
    assert main(["train", "state-classifier", "--data", str(fresh_dataset), "--out", str(out),
                 "--depth-dropout", "2"]) == 2
    assert "depth_dropout must be in [0, 1]; got 2.0" in capsys.readouterr().err


def test_the_shipped_model_reads_the_camera_factors_with_and_without_depth(fresh_steps):
    """Floors: 0.95 with depth is docs/perception.md's floor for the location factors. Without depth
    the floor is 0.90, set before measuring: the classifier must be usable on plain video (at
    most 1 error in 10 on what the camera shows, far below the ~30 % observer noise the paper
    assumed), while ~35 unoccluded steps leave room for a step or two of bad luck."""
    torch.set_num_threads(2)
    model = StateClassifier.load(SHIPPED)
    report = evaluate_steps(model, fresh_steps)
    assert report["n_steps"] - report["n_occluded"] >= 20
    for factor in ("onion", "end_effector"):
        assert report["with_depth"][f"accuracy_{factor}"] >= 0.95, report
        assert report["without_depth"][f"accuracy_{factor}"] >= 0.90, report
    # perception takes steps without depth as well
    plain = [(s.colors, None, s.inspection) for s in fresh_steps[:10]]
    perceived = perceive_steps(model, plain, inspection=None)
    assert len(perceived) == 10 and all(0 <= p.onion < len(Location) for p in perceived)


def test_missing_checkpoint_is_a_clear_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="no state-classifier checkpoint"):
        StateClassifier.load(tmp_path / "nope.pt")


def test_forward_shapes():
    model = StateClassifier(ClassifierConfig(width=64, height=48, channels=8))
    out = model(torch.zeros(2, 12, 48, 64))
    assert out["onion"].shape == (2, 4) and out["occluded"].shape == (2, 2)
    assert out["action"].shape == (2, 5) and out["waiting"].shape == (2, 2)
