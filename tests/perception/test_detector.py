"""The detector: assignment, augmentation, decoding and NMS, training on labelled images,
checkpoints and resume, and the ``train`` stage that reads them from a dataset."""

import json

import numpy as np
import pytest
import torch

from onionsort.cli import main
from onionsort.stages.train import DetectorTrainConfig, detector_images
from onionsort.stages.train import train_detector as train_stage
from perception import Detector, DetectorConfig, DetectorNet
from perception.assign import assign, decode, detection_loss
from perception.data import Sample, augment, letterbox, to_canvas, to_samples
from perception.detector import postprocess
from perception.model import grid_points
from perception.train_detector import TrainConfig, train_detector

TINY = DetectorConfig(width=128, height=96, channels=4)


@pytest.fixture(scope="module")
def tiny_dataset(tmp_path_factory):
    out = tmp_path_factory.mktemp("det") / "data"
    assert main(["dataset", "--frames", "30", "--robot-onions", "3",
                 "--steps-per-session", "5", "--frames-per-step",
                 "2", "--occlusion", "0.3", "--seed", "3", "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def tiny_images(tiny_dataset):
    """The stage's choice of labelled images of each split, as ``train_detector`` takes them."""
    return {split: detector_images(tiny_dataset, split, inspection_repeat=3 if split == "train"
                                   else 1, seed=1) for split in ("train", "val", "test")}


def test_every_box_gets_a_positive_on_its_level_and_points_take_the_smaller_box():
    points, strides = grid_points(256, 320)
    boxes = torch.tensor([[10.0, 10, 17, 17],      # 7 px: between stride-8 cell centres
                          [100, 100, 114, 114],    # 14 px: stride 8
                          [40, 40, 110, 110],      # 70 px: stride 16
                          [100, 100, 240, 230]])   # 140 px: stride 32
    matched = assign(points, strides, boxes)
    for g, stride in enumerate((8, 8, 16, 32)):
        pos = matched == g
        assert pos.any(), g
        assert torch.all(strides[pos] == stride)
    # a point inside both the 14 px box and the 140 px box (on different levels) is never
    # given to the larger one at stride 8
    assert not torch.any((matched == 3) & (strides == 8))
    assert torch.all(assign(points, strides, torch.zeros((0, 4))) == -1)


def test_decode_inverts_distances():
    points = torch.tensor([[20.0, 30.0]])
    ltrb = torch.tensor([[[5.0, 6.0, 7.0, 8.0]]])
    np.testing.assert_allclose(decode(points, ltrb)[0, 0].numpy(), [15, 24, 27, 38])


def test_augment_moves_boxes_with_the_image():
    img = np.zeros((96, 128, 3), np.uint8)
    img[40:50, 60:70] = 255
    sample = Sample(img, np.array([[60.0, 40, 70, 50]], np.float32), np.array([1]))
    rng = np.random.default_rng(0)
    for _ in range(20):
        out = augment(sample, rng, color=0.0)
        ys, xs = np.nonzero(out.image[..., 0] > 127)
        if len(out.boxes):
            np.testing.assert_allclose(out.boxes[0], [xs.min(), ys.min(), xs.max() + 1,
                                                      ys.max() + 1], atol=1.5)
            assert out.classes[0] == 1


def test_letterbox_round_trips_boxes():
    img = np.zeros((120, 160, 3), np.uint8)
    canvas, lb = letterbox(img, 320, 256)
    assert canvas.shape == (256, 320, 3) and lb.scale == 2.0
    s = to_canvas(img, [[10, 20, 30, 40]], [0], 320, 256)
    np.testing.assert_allclose(lb.to_image(s.boxes), [[10, 20, 30, 40]])


def test_postprocess_keeps_the_best_of_overlapping_boxes_per_class():
    config = DetectorConfig(score_threshold=0.3, iou_threshold=0.5)
    points = torch.tensor([[10.0, 10.0], [11.0, 10.0], [50.0, 50.0]])
    ltrb = torch.full((1, 3, 4), 5.0)
    logits = torch.tensor([[[3.0, -9.0], [2.0, 1.0], [-9.0, -9.0]]])
    (_, scores, classes), = postprocess(logits, ltrb, points, config)
    # class 0: two overlapping boxes -> the best one; class 1 survives on its own
    assert sorted(classes.tolist()) == [0, 1]
    assert scores[classes == 0].item() == pytest.approx(torch.sigmoid(torch.tensor(3.0)).item())


def test_loss_is_finite_and_falls_on_one_batch():
    torch.manual_seed(0)
    net = DetectorNet(TINY)
    points, strides = grid_points(TINY.height, TINY.width)
    x = torch.rand(2, 3, TINY.height, TINY.width)
    targets = [(torch.tensor([[20.0, 20, 34, 34]]), torch.tensor([0])),
               (torch.tensor([[60.0, 30, 90, 62], [5, 5, 12, 13]]), torch.tensor([1, 0]))]
    opt = torch.optim.Adam(net.parameters(), 1e-2)
    losses = []
    for _ in range(15):
        loss, info = detection_loss(*net(x), points, strides, targets)
        assert torch.isfinite(loss) and info["positives"] >= 3
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < 0.5 * losses[0]


def test_tiny_training_run_checkpoints_and_resumes_exactly(tiny_images, tmp_path, monkeypatch):
    import perception.train_detector as train_module

    config = TrainConfig(epochs=4, images_per_epoch=16, batch_size=4, lr=1e-2, seed=1)
    splits = tiny_images["train"], tiny_images["val"], tiny_images["test"]
    epochs = []
    full = train_detector(*splits, config, tmp_path / "a", TINY, on_epoch=epochs.append)
    assert [e["epoch"] for e in epochs] == [0, 1, 2, 3]
    losses = [h["train_loss"] for h in full["history"]]
    assert losses[-1] < losses[0]
    assert set(full["test"]) >= {"map50", "map50_95"}

    real, calls = train_module.evaluate_detector, []

    def interrupt_after_two_epochs(*args, **kwargs):
        calls.append(1)
        if len(calls) == 3:  # during the third epoch's evaluation
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(train_module, "evaluate_detector", interrupt_after_two_epochs)
    with pytest.raises(KeyboardInterrupt):
        train_detector(*splits, config, tmp_path / "b", TINY)
    monkeypatch.setattr(train_module, "evaluate_detector", real)
    resumed = train_detector(*splits, config, tmp_path / "b", TINY, resume=True)
    assert [h["train_loss"] for h in resumed["history"]] == pytest.approx(losses, rel=1e-5)
    a = torch.load(tmp_path / "a" / "detector_last.pt", weights_only=False)["model"]
    b = torch.load(tmp_path / "b" / "detector_last.pt", weights_only=False)["model"]
    for k in a:
        torch.testing.assert_close(a[k], b[k], rtol=1e-4, atol=1e-5)

    det, again = (Detector.load(tmp_path / "a" / "detector.pt") for _ in range(2))
    images = [np.random.default_rng(0).integers(0, 255, (240, 320, 3), dtype=np.uint8),
              np.zeros((120, 160, 3), np.uint8)]
    for d1, d2 in zip(det.detect(images, score_threshold=0.0),
                      again.detect(images, score_threshold=0.0), strict=True):
        np.testing.assert_allclose(d1.boxes, d2.boxes)
        np.testing.assert_allclose(d1.scores, d2.scores)
    assert det.detect(images)[1].boxes.shape[1] == 4


def test_resume_without_a_checkpoint_and_bad_checkpoints_are_clear_errors(tmp_path):
    image = (np.zeros((24, 32, 3), np.uint8), [[1, 2, 9, 9]], [0])
    with pytest.raises(FileNotFoundError, match="cannot resume"):
        train_detector([image], [image], [], TrainConfig(epochs=1), tmp_path / "x", TINY,
                       resume=True)
    with pytest.raises(ValueError, match="val must hold at least one labelled image"):
        train_detector([image], [], [], TrainConfig(epochs=1), tmp_path / "x", TINY)
    with pytest.raises(FileNotFoundError, match="not a dataset folder"):
        train_stage(DetectorTrainConfig(data=tmp_path, out=tmp_path / "x"))
    with pytest.raises(FileNotFoundError, match="cannot resume"):
        train_stage(DetectorTrainConfig(data=tmp_path, out=tmp_path / "x", resume=True))
    with pytest.raises(ValueError, match="images_per_epoch must be >= 1; got 0"):
        DetectorTrainConfig(data=tmp_path, out=tmp_path / "x", images_per_epoch=0)
    with pytest.raises(FileNotFoundError, match="no detector checkpoint"):
        Detector.load(tmp_path / "missing.pt")
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match="not a detector checkpoint"):
        Detector.load(tmp_path / "junk.pt")
    with pytest.raises(ValueError, match="epochs must be >= 1"):
        TrainConfig(epochs=0)
    with pytest.raises(ValueError, match="images must be"):
        Detector(DetectorNet(TINY)).detect([np.zeros((10, 10), np.uint8)])


def test_samples_of_labelled_images_share_repeats():
    img = np.zeros((120, 160, 3), np.uint8)
    triple = (img, [[10, 20, 30, 40]], [1])
    samples = to_samples([triple, triple, (img, [], [])], 320, 256)
    assert samples[0] is samples[1] and samples[2] is not samples[0]
    np.testing.assert_allclose(samples[0].boxes, [[20, 48, 60, 88]])
    assert samples[2].boxes.shape == (0, 4) and samples[0].classes.tolist() == [1]
    with pytest.raises(ValueError, match="images must be"):
        to_samples([(np.zeros((10, 10)), [], [])], 320, 256)


def test_the_stage_reads_camera_frames_and_inspection_views(tiny_dataset, tiny_images):
    from recordings.labels.dataset import read_split

    camera = list(read_split(tiny_dataset, "train"))
    views = list(read_split(tiny_dataset, "train", view="inspection"))
    with_onion = [v for v in views if v.record["boxes"]]
    train = tiny_images["train"]
    assert len(train) >= len(camera) + 3 * len(with_onion)
    assert len(train) <= len(camera) + 3 * len(with_onion) + len(views) - len(with_onion)
    assert len({id(t) for t in train}) == len(train) - 2 * len(with_onion)  # repeats shared


def test_the_stage_trains_and_resumes_through_the_cli(tiny_dataset, tmp_path, capsys):
    out = tmp_path / "run"
    args = ["train", "detector", "--data", str(tiny_dataset), "--out", str(out), "--epochs",
            "1", "--images-per-epoch", "4", "--batch-size", "4"]
    assert main(args) == 0
    assert "detector, test split: mAP@0.5" in capsys.readouterr().out
    assert (out / "detector.pt").is_file() and (out / "detector_last.pt").is_file()
    assert main([*args, "--resume"]) == 0  # nothing left to do: same metrics file
    assert json.loads((out / "detector_metrics.json").read_text())["train"]["epochs"] == 1
