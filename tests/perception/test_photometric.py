"""Photometric augmentation: a camera of its own per training sample, in training only.

Each trainer is run on a tiny in-memory set with a spy in place of
:class:`perception.photometric.PhotometricAugment`'s call: it must be called exactly once per
training sample and epoch (so never on validation samples, which every epoch also reads), and
never by what reads a trained model (inference, evaluation).
"""

from dataclasses import replace

import numpy as np
import pytest
import torch

from perception import Detector
from perception.photometric import PhotometricAugment, RandomGamma, RandomJPEG, WhiteBalance
from tests.perception.test_detector import TINY as TINY_DETECTOR
from tests.perception.test_inspection import _blob_crops
from tests.state_abstraction.test_classifier import TINY as TINY_CLASSIFIER
from tests.state_abstraction.test_classifier import synthetic_steps


@pytest.fixture
def spy(monkeypatch):
    """The shapes of every batch the augmentation was called on."""
    calls = []
    real = PhotometricAugment.__call__

    def recording(self, images):
        calls.append(tuple(images.shape))
        return real(self, images)

    monkeypatch.setattr(PhotometricAugment, "__call__", recording)
    return calls


def test_a_camera_per_call_reproducible_from_torch_seed():
    x = torch.rand(3, 3, 24, 32)
    augment = PhotometricAugment()
    torch.manual_seed(5)
    a = augment(x)
    torch.manual_seed(5)
    b = augment(x)
    torch.testing.assert_close(a, b)
    assert a.shape == x.shape and a.dtype == x.dtype
    assert float(a.min()) >= 0.0 and float(a.max()) <= 1.0
    c = augment(x)  # the next draw: another camera
    assert not torch.equal(a, c)
    torch.testing.assert_close(PhotometricAugment(strength=0)(x), x)
    assert augment(x.half()).dtype == torch.float16
    # white balance scales red and blue the opposite way; gamma > 1 darkens
    torch.manual_seed(0)
    wb = WhiteBalance(mired=60)
    out = wb(torch.full((3, 4, 4), 0.5))
    assert not torch.allclose(out[0], out[2]) and torch.allclose(out[1], torch.tensor(0.5))
    assert float(RandomGamma((1.5, 1.5))(torch.full((3, 2, 2), 0.5)).max()) < 0.4
    smooth = torch.linspace(0, 1, 3 * 16 * 16).reshape(3, 16, 16)
    coded = RandomJPEG((30, 30))(smooth[None])
    assert coded.shape == (1, 3, 16, 16) and 0 < float((coded - smooth).abs().mean()) < 0.05


@pytest.mark.parametrize("bad", [torch.rand(4, 8, 8), torch.rand(2, 1, 8, 8),
                                 torch.zeros(3, 8, 8, dtype=torch.uint8), np.zeros((3, 8, 8))])
def test_bad_inputs_are_refused(bad):
    with pytest.raises(ValueError, match=r"float tensor \[n, 3, H, W\]"):
        PhotometricAugment()(bad)


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="strength must be in"):
        PhotometricAugment(strength=-1)
    with pytest.raises(ValueError, match="mired must be in"):
        WhiteBalance(mired=500)
    with pytest.raises(ValueError, match="gamma must be a range"):
        RandomGamma((1.2, 0.9))
    with pytest.raises(ValueError, match="quality must be a range"):
        RandomJPEG((0, 90))


def test_the_state_classifier_augments_its_training_steps_only(spy, tmp_path):
    from state_abstraction.classifier import StateClassifier, steps_to_tensors, train_classifier

    config = replace(TINY_CLASSIFIER, epochs=2)
    train, val, test = synthetic_steps(12, 0), synthetic_steps(6, 1), synthetic_steps(6, 2)
    metrics = train_classifier(train, val, test, config, tmp_path / "on",
                               photometric=PhotometricAugment())
    # one call per training step and epoch, on its 3 frames' colours: none on val or test
    assert spy == [(3, 3, 24, 32)] * 12 * 2
    assert metrics["photometric"] == "PhotometricAugment(strength=1.0)"
    spy.clear()
    model = StateClassifier.load(tmp_path / "on" / "state_classifier.pt")
    model.predict(steps_to_tensors(test, config)[0])
    assert spy == []
    off = train_classifier(train, val, test, config, tmp_path / "off")
    assert spy == [] and off["photometric"] is None


def test_the_detector_augments_its_training_images_only(spy, tmp_path):
    from perception.train_detector import TrainConfig, evaluate_detector, train_detector

    rng = np.random.default_rng(0)
    images = [(rng.integers(0, 255, (48, 64, 3), dtype=np.uint8), [[10, 10, 30, 30]], [k % 2])
              for k in range(6)]
    config = TrainConfig(epochs=2, images_per_epoch=4, batch_size=2)
    train_detector(images, images[:2], images[:2], config, tmp_path / "on", TINY_DETECTOR)
    assert spy == [(3, TINY_DETECTOR.height, TINY_DETECTOR.width)] * 4 * 2
    spy.clear()
    detector = Detector.load(tmp_path / "on" / "detector.pt")
    detector.detect([image for image, _, _ in images])
    from perception.data import to_samples

    evaluate_detector(detector.net, to_samples(images, TINY_DETECTOR.width,
                                               TINY_DETECTOR.height))
    assert spy == []


def test_the_inspection_classifier_augments_its_training_crops_only(spy):
    from perception.inspection import CROP_SIZE, InspectionNetConfig
    from perception.train_inspection import (
        CONTEXT_SIZE,
        CropSet,
        InspectionTrainConfig,
        train_inspection,
    )

    rng = np.random.default_rng(0)
    train_x, train_y = _blob_crops(8, rng, CONTEXT_SIZE)
    val_x, val_y = _blob_crops(4, rng, CROP_SIZE)
    train = CropSet(train_x, train_y, train_y, np.ones(8))
    val = CropSet(val_x, val_y, val_y, np.ones(4))
    config = InspectionTrainConfig(epochs=2, batch_size=4)
    classifier, _ = train_inspection(train, val, config, InspectionNetConfig(width=4))
    assert spy == [(3, CROP_SIZE, CROP_SIZE)] * 8 * 2
    spy.clear()
    classifier.probabilities(val_x)
    classifier.rot_probabilities(val_x)
    assert spy == []


def test_a_detector_run_saved_before_augmentation_resumes_as_trained_without_it(tmp_path):
    from perception.train_detector import TrainConfig, train_detector

    rng = np.random.default_rng(1)
    images = [(rng.integers(0, 255, (48, 64, 3), dtype=np.uint8), [[10, 10, 30, 30]], [0])
              for _ in range(2)]
    config = TrainConfig(epochs=1, images_per_epoch=2, batch_size=2, photometric=False)
    train_detector(images, images, [], config, tmp_path, TINY_DETECTOR)
    last = tmp_path / "detector_last.pt"
    ckpt = torch.load(last, weights_only=False)
    del ckpt["train_config"]["photometric"]  # as a run of an earlier version saved it
    torch.save(ckpt, last)
    train_detector(images, images, [], config, tmp_path, TINY_DETECTOR, resume=True)
    with pytest.raises(ValueError, match="cannot resume"):
        train_detector(images, images, [], replace(config, photometric=True), tmp_path,
                       TINY_DETECTOR, resume=True)
