"""``bench/colour_constancy_ceiling.py``: the true gains read off a level against the same
seed at ``clean``, and the two perfect colour constancies (the measurement itself:
docs/perception.md)."""

import dataclasses

import numpy as np
import pytest

from bench.colour_constancy_ceiling import ColourUndone, ConstantLight, true_gains
from onionsort.cli import main as onionsort
from onionsort.stages.calibrate import SessionCameras


def _render(root, level):
    assert onionsort(["dataset", "--frames", "36", "--steps-per-session", "4",
                      "--robot-onions", "0", "--seed", "8", "--difficulty", level,
                      "--workers", "1", "--out", str(root)]) == 0


def test_the_true_gain_undoes_the_levels_light(tmp_path):
    _render(tmp_path / "paper", "paper")
    _render(tmp_path / "clean", "clean")
    gains = true_gains(tmp_path / "paper", tmp_path / "clean")
    assert {kind for kind, _ in gains} == {"session"}
    values = np.array(list(gains.values()))
    # the level lights each session with a gain and a cast of its own (log sd 0.18)
    assert values.shape == (3, 3) and np.ptp(values) > 0.05
    assert np.all((values > 0.4) & (values < 2.5))
    # a dataset that is not the same seed at clean is refused
    _render(tmp_path / "other", "clean")
    (tmp_path / "other" / "test" / "labels.json").write_text("[]")
    with pytest.raises(ValueError, match=r"is not .* seed at clean"):
        true_gains(tmp_path / "paper", tmp_path / "other")


def test_constant_light_divides_by_the_gain_and_undone_colour_keeps_the_rest():
    image = np.full((8, 8, 3), 100, np.uint8)
    light = ConstantLight({("session", 2): np.array([0.5, 1.0, 2.0])})
    out = light(image, {"session": 2})
    assert out[0, 0].tolist() == [200, 100, 50]
    with pytest.raises(KeyError):
        light(image, {"session": 3})
    cameras = SessionCameras(7)
    record = {"session": 1}
    undone = ColourUndone(cameras)(image, record)
    camera = cameras.camera(record)
    kept = dataclasses.replace(camera, gamma=1.0, exposure_ev=0.0,
                               temperature_k=6500.0)
    np.testing.assert_array_equal(undone, kept.apply(image))
    # the camera's colour is gone: the mean stays near the input's, unlike through the camera
    assert abs(float(undone.mean()) - 100) < abs(float(cameras(image, record).mean()) - 100)
