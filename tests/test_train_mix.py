"""Fine-tuning on a mix: ``train detector|state-classifier|inspection`` with ``--init`` and
several ``--data`` weighed by ``--data-weights``."""

from dataclasses import replace

import numpy as np
import pytest
import torch

from onionsort.cli import main
from onionsort.stages.inspection import InspectionTrainStageConfig
from onionsort.stages.train import ClassifierTrainConfig, DetectorTrainConfig
from recordings.labels.dataset import read_records, read_steps
from tests.perception.test_inspection import _blob_crops
from tests.state_abstraction.test_classifier import TINY, synthetic_steps
from tests.test_label import exported, rendered  # noqa: F401  (module fixtures)


def _parameters(module: torch.nn.Module) -> dict:
    return {k: v.detach().clone() for k, v in module.named_parameters()}


def _close(a: dict, b: dict, atol: float) -> bool:
    return a.keys() == b.keys() and all(torch.allclose(a[k], b[k], atol=atol) for k in a)


def test_the_state_classifier_starts_from_its_init(tmp_path):
    from state_abstraction.classifier import StateClassifier, train_classifier

    train, val = synthetic_steps(24, 0), synthetic_steps(8, 1)
    train_classifier(train, val, [], replace(TINY, epochs=2), tmp_path / "a")
    start = _parameters(StateClassifier.load(tmp_path / "a" / "state_classifier.pt"))
    still = replace(TINY, epochs=1, lr=1e-9, seed=5)  # a step too small to move a weight
    train_classifier(train, val, [], still, tmp_path / "b", init=tmp_path / "a" /
                     "state_classifier.pt")
    assert _close(_parameters(StateClassifier.load(tmp_path / "b" / "state_classifier.pt")),
                  start, 1e-5)
    train_classifier(train, val, [], still, tmp_path / "c")  # from scratch: elsewhere
    assert not _close(_parameters(StateClassifier.load(tmp_path / "c" /
                                                       "state_classifier.pt")), start, 1e-3)
    with pytest.raises(ValueError, match=r"cannot start from .* width 32"):
        train_classifier(train, val, [], replace(still, width=64), tmp_path / "d",
                         init=tmp_path / "a" / "state_classifier.pt")


def test_the_inspection_classifier_starts_from_its_init(tmp_path):
    from perception.inspection import CROP_SIZE, InspectionNetConfig
    from perception.train_inspection import (
        CONTEXT_SIZE,
        CropSet,
        InspectionTrainConfig,
        train_inspection,
    )

    rng = np.random.default_rng(0)
    x, y = _blob_crops(32, rng, CONTEXT_SIZE)
    vx, vy = _blob_crops(16, rng, CROP_SIZE)
    train, val = CropSet(x, y, y, np.ones(len(y))), CropSet(vx, vy, vy, np.ones(len(vy)))
    net = InspectionNetConfig(width=8)
    first, _ = train_inspection(train, val, InspectionTrainConfig(epochs=2, batch_size=16), net)
    path = first.save(tmp_path / "inspection_classifier.pt")
    again, _ = train_inspection(train, val, InspectionTrainConfig(epochs=1, batch_size=16,
                                                                  lr=1e-9, seed=3), net,
                                init=path)
    assert _close(_parameters(again.net), _parameters(first.net), 1e-5)
    with pytest.raises(ValueError, match="cannot start from"):
        train_inspection(train, val, InspectionTrainConfig(epochs=1), InspectionNetConfig(
            width=12), init=path)


def test_data_weights_are_one_positive_integer_per_dataset(tmp_path):
    config = DetectorTrainConfig(data=tmp_path, out=tmp_path / "x")
    assert config.data == (tmp_path,) and config.data_weights == (1,)
    both = ClassifierTrainConfig(data=[tmp_path, tmp_path / "b"], out=tmp_path / "x",
                                 data_weights=(3, 1))
    assert both.data_weights == (3, 1)
    for weights, message in (((1,), "one weight per dataset \\(2\\); got 1"),
                             ((2, 0), "positive integers"), ((1.5, 1), "positive integers")):
        with pytest.raises(ValueError, match=message):
            InspectionTrainStageConfig(data=(tmp_path, tmp_path), out=tmp_path / "x",
                                       data_weights=weights)


def test_each_trainer_counts_a_datasets_training_frames_its_weights_times(
        rendered, exported, tmp_path, monkeypatch):  # noqa: F811
    """Three stages, two datasets (the rendered one and its COCO import) at 3,1: the
    training set holds the first's frames three times, the second's once; val and test once
    each."""
    import perception.train_detector
    import perception.train_inspection
    import state_abstraction.classifier
    from onionsort.stages.inspection import train_inspection_stage
    from onionsort.stages.train import train_detector, train_state_classifier

    lab = tmp_path / "lab"
    assert main(["label", "import", str(exported["coco"]), "--format", "coco",
                 "--out", str(lab)]) == 0
    seen = {}

    def fake(name):
        def record(train, val, test=(), *args, **kwargs):
            if name == "inspection":  # CropSets
                seen[name] = (len(train.labels), len(val.labels), 0, kwargs.get("init"),
                              train.weights)
            else:
                seen[name] = (len(train), len(val), len(test), kwargs.get("init"), None)
            raise KeyboardInterrupt  # stop here: what it was given is what counts
        return record

    monkeypatch.setattr(perception.train_detector, "train_detector", fake("detector"))
    monkeypatch.setattr(state_abstraction.classifier, "train_classifier", fake("classifier"))
    monkeypatch.setattr(perception.train_inspection, "train_inspection", fake("inspection"))
    init = tmp_path / "start.pt"
    init.write_bytes(b"a checkpoint")
    for stage, config in (
            (train_detector, DetectorTrainConfig(data=(rendered, lab), out=tmp_path / "d",
                                                 data_weights=(3, 1), init=init)),
            (train_state_classifier, ClassifierTrainConfig(
                data=(rendered, lab), out=tmp_path / "s", data_weights=(3, 1), init=init)),
            (train_inspection_stage, InspectionTrainStageConfig(
                data=(rendered, lab), out=tmp_path / "i", data_weights=(1, 1))),
            (train_inspection_stage, InspectionTrainStageConfig(
                data=(rendered, lab), out=tmp_path / "i", data_weights=(3, 1), init=init))):
        if "inspection" in seen:
            seen["inspection (1, 1)"] = seen.pop("inspection")
        with pytest.raises(KeyboardInterrupt):
            stage(config)
    from onionsort.stages.train import detector_images

    n_det = {s: len(detector_images(rendered, s, inspection_repeat=3 if s == "train" else 1))
             for s in ("train", "val", "test")}
    assert seen["detector"][:3] == (4 * n_det["train"], 2 * n_det["val"], 2 * n_det["test"])
    steps = {s: sum(len(k) for k in read_steps(rendered, s, 3)) for s in ("train", "val")}
    assert seen["classifier"][:2] == (4 * steps["train"], 2 * steps["val"])
    assert {seen[k][3] for k in ("detector", "classifier", "inspection")} == {init}
    from onionsort.stages.inspection import inspection_views

    # the rendered views, then the imported ones: three times the weight they have at 1,1
    ratio = np.asarray(seen["inspection"][4]) / np.asarray(seen["inspection (1, 1)"][4])
    n = len(inspection_views(rendered, "train"))
    assert 0 < n < len(ratio) and np.allclose(ratio[:n], 3 * ratio[n:][0])
    assert np.allclose(ratio[n:], ratio[n:][0])
    assert len(read_records(lab, "train")) == len(read_records(rendered, "train"))


@pytest.mark.parametrize("argv, words", [
    (["--data-weights", "3,0"], ["expected positive integers", "'3,0'"]),
    (["--data-weights", "3,1,1"], ["one weight per dataset (2); got 3"]),
    (["--init", "{d}/nothing.pt"], ["nothing.pt: no such"]),
])
def test_bad_mixes_are_one_line(tmp_path, capsys, rendered, argv, words):  # noqa: F811
    argv = [a.format(d=tmp_path) for a in argv]
    for model in ("state-classifier", "inspection"):
        try:
            code = main(["train", model, "--data", str(rendered), "--data", str(rendered),
                         *argv, "--epochs", "1", "--out", str(tmp_path / "out")])
        except SystemExit as exc:
            code = exc.code
        err = capsys.readouterr().err.splitlines()
        assert code == 2 and len(err) == 1, err
        assert all(w in err[0] for w in words), err


def test_the_detector_trains_through_other_cameras_at_the_frames_resolution(
        rendered, tmp_path, monkeypatch):  # noqa: F811
    """``--through-cameras 11,12``: the training split gets its camera frames again through
    each seed's session cameras (as ``eval-perception --camera-shift`` sees them), the val split
    through the first seed's; the frames as rendered stay."""
    import perception.train_detector
    from onionsort.stages.cameras import SessionCameras
    from onionsort.stages.train import detector_images, train_detector
    from recordings.labels.dataset import read_split

    seen = {}

    def record(train, val, test=(), *args, **kwargs):
        seen.update(train=train, val=val)
        raise KeyboardInterrupt

    monkeypatch.setattr(perception.train_detector, "train_detector", record)
    with pytest.raises(KeyboardInterrupt):
        train_detector(DetectorTrainConfig(data=rendered, out=tmp_path / "d",
                                           through_cameras=(11, 12)))
    frames = {s: list(read_split(rendered, s)) for s in ("train", "val")}
    plain = {s: detector_images(rendered, s, inspection_repeat=3 if s == "train" else 1)
             for s in ("train", "val")}
    assert len(seen["train"]) == len(plain["train"]) + 2 * len(frames["train"])
    assert len(seen["val"]) == len(plain["val"]) + len(frames["val"])
    first = frames["train"][0]
    for k, seed in enumerate((11, 12)):  # after the frames as rendered, one pass per seed
        image, boxes, classes = seen["train"][len(plain["train"]) + k * len(frames["train"])]
        assert np.array_equal(image, SessionCameras(seed)(first.color, first.record))
        assert not np.array_equal(image, first.color)
        assert (boxes, classes) == (first.record["boxes"], first.record["classes"])
    assert np.array_equal(seen["train"][0][0], first.color)
    with pytest.raises(ValueError, match="through_cameras names seed 3 twice"):
        DetectorTrainConfig(data=rendered, out=tmp_path / "e", through_cameras=(3, 3))
