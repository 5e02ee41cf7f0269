"""The state abstraction: frames -> factored onion-sorting state (or occluded), and calibration of
its errors into the observation model of ``irl``."""

from state_abstraction.calibration import Calibration, ConfusionMatrix, calibrate, load_calibration

__all__ = ["Calibration", "ConfusionMatrix", "calibrate", "load_calibration"]
