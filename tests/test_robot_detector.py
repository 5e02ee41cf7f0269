"""The Sawyer's own detector (``robot_detector.pt``): where a models folder has one, it alone
finds the onion in the robot's views, in the inspection, its measurement, the fusion's fit and
the detector's mAP, while the sorter's views and the main camera keep the shared detector."""

import dataclasses

import numpy as np
import pytest

from onionsort.stages import DatasetConfig, make_dataset
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


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("robot-detector") / "data"
    make_dataset(DatasetConfig(out=root, frames=60, steps_per_session=5, robot_onions=12,
                               robot_views=2, seed=5))
    return root


@pytest.fixture(scope="module")
def shipped():
    return PerceptionModels.load(device="cpu")


def test_a_folder_with_a_robot_detector_loads_it_for_the_robots_views_alone(tmp_path, shipped):
    for path in DEFAULT_MODELS.iterdir():
        if path.is_file():
            (tmp_path / path.name).write_bytes(path.read_bytes())
    assert shipped.robot_detector is None
    assert shipped.detector_for("robot") is shipped.detector
    assert "robot_detector_sha256" not in shipped.describe()
    (tmp_path / ROBOT_DETECTOR_FILE).write_bytes((DEFAULT_MODELS / "detector.pt").read_bytes())
    models = PerceptionModels.load(tmp_path, device="cpu")
    assert models.robot_detector is not None and models.robot_detector is not models.detector
    assert models.detector_for("robot") is models.robot_detector
    assert models.detector_for("sorter") is models.detector
    assert models.inspector(camera="robot").detector is models.robot_detector
    assert models.inspector().detector is models.detector
    described = models.describe()
    assert described["robot_detector_sha256"] == described["detector_sha256"]  # the same file
    with pytest.raises(ValueError, match="camera must be"):
        models.detector_for("main")


def test_each_view_is_read_by_its_cameras_detector_in_order(dataset, shipped):
    one = inspection_views(dataset, "all", detector=shipped.detector)
    sorter, robot = Counting(shipped.detector), Counting(shipped.detector)
    two = inspection_views(dataset, "all", detector=sorter, robot_detector=robot)
    is_robot = one.source == "robot"
    assert robot.images == int(is_robot.sum()) > 0
    assert sorter.images == int((~is_robot).sum()) > 0
    for name in ("crops", "found", "onion", "view", "labels"):  # the same rows, in order
        np.testing.assert_array_equal(getattr(one, name), getattr(two, name))
    blind = inspection_views(dataset, "all", detector=shipped.detector,
                             robot_detector=Counting(shipped.detector, blind=True))
    assert not blind.found[is_robot].any()
    np.testing.assert_array_equal(blind.found[~is_robot], one.found[~is_robot])
    np.testing.assert_array_equal(blind.crops[~is_robot], one.crops[~is_robot])


def test_the_measurements_read_the_robots_views_with_its_detector(dataset, shipped):
    blind = dataclasses.replace(shipped, robot_detector=Counting(shipped.detector, blind=True))
    before, after = (measure_inspection(m, dataset, "all") for m in (shipped, blind))
    for level, figures in before["levels"].items():
        assert figures["robot"]["found"] > 0
        assert after["levels"][level]["robot"]["found"] == 0
        assert after["levels"][level]["human"] == figures["human"]
    mine, theirs = (detector_map(m, dataset, "all") for m in (shipped, blind))
    assert theirs["camera"] == mine["camera"]
    assert theirs["inspection"]["map50"] < mine["inspection"]["map50"]
