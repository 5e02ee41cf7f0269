"""The state classifier trains end to end on rendered steps and round-trips its checkpoint."""

import json

import numpy as np
import pytest
import torch

from onionsort.cli import main
from state_abstraction.classifier import (
    ClassifierConfig,
    StateClassifier,
    load_steps,
    step_input,
    train_classifier,
)


@pytest.fixture(scope="module")
def tiny_dataset(tmp_path_factory):
    out = tmp_path_factory.mktemp("sc") / "data"
    assert main(["dataset", "--frames", "36", "--robot-onions", "0",
                 "--steps-per-session", "4", "--frames-per-step",
                 "3", "--occlusion", "0.5", "--seed", "5", "--out", str(out)]) == 0
    return out


def test_tiny_training_run_loss_falls_and_checkpoint_round_trips(tiny_dataset, tmp_path):
    config = ClassifierConfig(width=64, height=48, channels=8, epochs=8, batch_size=8, seed=0)
    metrics = train_classifier(tiny_dataset, tmp_path, config)
    losses = [h["train_loss"] for h in metrics["history"]]
    assert losses[-1] < losses[0]
    for v in metrics["test"].values():
        assert 0.0 <= v <= 1.0
    saved = json.loads((tmp_path / "state_classifier_metrics.json").read_text())
    assert saved["config"]["channels"] == 8

    model = StateClassifier.load(tmp_path / "state_classifier.pt")
    x, y = load_steps(tiny_dataset, "test", config)
    again = StateClassifier.load(tmp_path / "state_classifier.pt")
    p1, p2 = model.predict(x), again.predict(x)
    for k in p1:
        np.testing.assert_allclose(p1[k], p2[k])
        np.testing.assert_allclose(p1[k].sum(axis=1), 1.0, rtol=1e-5)
    assert set(y) == {"onion", "end_effector", "action", "waiting", "occluded"}
    assert x.shape[1:] == (12, 48, 64)


def test_missing_checkpoint_is_a_clear_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="no state-classifier checkpoint"):
        StateClassifier.load(tmp_path / "nope.pt")


def test_forward_shapes():
    model = StateClassifier(ClassifierConfig(width=64, height=48, channels=8))
    out = model(torch.zeros(2, 12, 48, 64))
    assert out["onion"].shape == (2, 4) and out["occluded"].shape == (2, 2)
    assert out["action"].shape == (2, 5) and out["waiting"].shape == (2, 2)


def test_a_step_with_the_wrong_number_of_frames_is_refused():
    config = ClassifierConfig(width=64, height=48, frames=3)
    color, depth = np.zeros((240, 320, 3), np.uint8), np.ones((240, 320), np.float32)
    assert step_input([color] * 3, [depth] * 3, config).shape == (12, 48, 64)
    with pytest.raises(ValueError, match="a step must have 3 frames"):
        step_input([color] * 2, [depth] * 2, config)
