"""The Sawyer's own detector (``robot_detector.pt``): where a models folder has one, it alone
finds the onion in the robot's views, in the inspection, its measurement, the fusion's fit,
the classifier's training and the detector's mAP, while the sorter's views and the main camera
keep the shared detector."""

import dataclasses
import shutil

import numpy as np
import pytest

from onionsort.stages import DatasetConfig, make_dataset
from onionsort.stages import inspection as stage
from onionsort.stages.calibrate import detector_map
from onionsort.stages.inspection import inspection_views, measure_inspection
from onionsort.stages.models import DEFAULT_MODELS, ROBOT_DETECTOR_FILE, PerceptionModels
from perception.detector import Detections


class Counting:
    """A detector that counts the images it is asked about; ``blind`` finds nothing in them."""

    def __init__(self, inner, blind: bool = False):
        self.inner, self.blind, self.images = inner, blind, 0

    def detect(self, images, **kwargs):
        self.images += len(images)
        if self.blind:
            return [Detections(np.zeros((0, 4)), np.zeros(0), np.zeros(0, int)) for _ in images]
        return self.inner.detect(images, **kwargs)


class ByLook:
    """A detector whose one box is placed by the image's mean colour and ``shift``, so that a
    crop shows which image, and which detector, it was cut for."""

    def __init__(self, shift: int):
        self.shift = shift

    def detect(self, images, **kwargs):
        out = []
        for image in images:
            h, w = np.asarray(image).shape[:2]
            at = int(np.asarray(image).mean() * 7) % 11 + self.shift
            x, y = w // 2 - 20 + at, h // 2 - 20 + at
            out.append(Detections(np.array([[x, y, x + 30, y + 26]], float),
                                  np.array([0.9]), np.array([0])))
        return out


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("robot-detector") / "data"
    make_dataset(DatasetConfig(out=root, frames=60, steps_per_session=5, robot_onions=12,
                               robot_views=2, seed=5))
    return root


@pytest.fixture(scope="module")
def shipped():
    return PerceptionModels.load(device="cpu")


@pytest.fixture
def folder(tmp_path):
    """The shipped models, with the shipped detector as the Sawyer's own too."""
    shutil.copytree(DEFAULT_MODELS, tmp_path / "models")
    shutil.copy(DEFAULT_MODELS / "detector.pt", tmp_path / "models" / ROBOT_DETECTOR_FILE)
    return tmp_path / "models"


def test_a_folder_with_a_robot_detector_loads_it_for_the_robots_views_alone(folder, shipped):
    assert shipped.robot_detector is None
    assert shipped.detector_for("robot") is shipped.detector
    assert "robot_detector_sha256" not in shipped.describe()
    models = PerceptionModels.load(folder, device="cpu")
    assert models.robot_detector is not None and models.robot_detector is not models.detector
    assert models.detector_for("robot") is models.robot_detector
    assert models.detector_for("sorter") is models.detector
    assert models.inspector(camera="robot").detector is models.robot_detector
    assert models.inspector().detector is models.detector
    described = models.describe()
    assert described["robot_detector_sha256"] == described["detector_sha256"]  # the same file
    with pytest.raises(ValueError, match="camera must be"):
        models.detector_for("main")
    found = stage._load_detectors(folder, "cpu")  # what `train inspection --detector` reads
    assert found["robot_detector"] is not None and found["robot_detector"] is not found["detector"]
    assert stage._load_detectors(None, "cpu")["robot_detector"] is None


@pytest.mark.parametrize("batch_size", [2, 5])
def test_each_view_is_cut_round_its_cameras_detectors_box_in_order(dataset, batch_size):
    sorter, robot = ByLook(0), ByLook(5)
    # one view at a time: each row is filled as it is read, the order cannot slip
    alone = {d: inspection_views(dataset, "all", detector=d, batch_size=1)
             for d in (sorter, robot)}
    mixed = inspection_views(dataset, "all", detector=sorter, robot_detector=robot,
                             batch_size=batch_size)
    is_robot = mixed.source == "robot"
    assert is_robot.sum() > batch_size and (~is_robot).sum() > batch_size  # flushed mid-read
    np.testing.assert_array_equal(mixed.crops[is_robot], alone[robot].crops[is_robot])
    np.testing.assert_array_equal(mixed.crops[~is_robot], alone[sorter].crops[~is_robot])
    assert not np.array_equal(alone[robot].crops[is_robot], alone[sorter].crops[is_robot])
    for name in ("found", "onion", "view", "labels", "source"):
        np.testing.assert_array_equal(getattr(mixed, name), getattr(alone[sorter], name))


def test_the_detectors_each_see_their_cameras_views_alone(dataset, shipped):
    sorter, robot = Counting(shipped.detector), Counting(shipped.detector)
    views = inspection_views(dataset, "all", detector=sorter, robot_detector=robot)
    assert robot.images == int((views.source == "robot").sum()) > 0
    assert sorter.images == int((views.source != "robot").sum()) > 0
    with pytest.raises(ValueError, match="needs a detector"):
        inspection_views(dataset, "all", robot_detector=robot)


def test_the_measurements_read_the_robots_views_with_its_detector(dataset, shipped):
    blind = dataclasses.replace(shipped, robot_detector=Counting(shipped.detector, blind=True))
    before, after = (measure_inspection(m, dataset, "all") for m in (shipped, blind))
    for level, figures in before["levels"].items():
        assert figures["robot"]["found"] > 0
        assert after["levels"][level]["robot"]["found"] == 0
        assert after["levels"][level]["human"] == figures["human"]
    mine = detector_map(shipped, dataset, "all")
    sorter, robot = Counting(shipped.detector), Counting(shipped.detector, blind=True)
    theirs = detector_map(dataclasses.replace(shipped, detector=sorter, robot_detector=robot),
                          dataset, "all")
    from recordings.labels.dataset import read_split, split_names

    robot_frames = sum(frame.record.get("source") == "robot" for name in split_names("all")
                       for frame in read_split(dataset, name, view="inspection"))
    assert robot.images == robot_frames > 0  # the Sawyer's frames, and none other
    assert theirs["camera"] == mine["camera"]
    assert theirs["inspection"]["map50"] < mine["inspection"]["map50"]


def test_the_fusion_fit_and_the_robots_training_read_its_views_with_its_detector(
        dataset, folder, shipped, monkeypatch, tmp_path):
    from onionsort.configs.inspection import FusionCalibrationConfig
    from onionsort.stages.inspection import InspectionTrainStageConfig, train_inspection_stage

    blind = Counting(shipped.detector, blind=True)
    load = PerceptionModels.load
    monkeypatch.setattr(PerceptionModels, "load", classmethod(
        lambda cls, *a, **k: dataclasses.replace(load(*a, **k), robot_detector=blind)))
    with pytest.raises(ValueError, match="hold no robot view"):
        stage.fit_robot_fusion_stage(FusionCalibrationConfig(
            data=dataset, out=tmp_path / "fit", models=folder, device="cpu"))
    assert blind.images > 0
    monkeypatch.setattr(stage, "_load_detectors", lambda *_: {"detector": shipped.detector,
                                                              "robot_detector": blind})
    with pytest.raises(ValueError, match="hold no robot views in their val"):
        train_inspection_stage(InspectionTrainStageConfig(
            data=dataset, out=tmp_path / "train", camera="robot", epochs=1, device="cpu"))
