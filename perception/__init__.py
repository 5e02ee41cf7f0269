"""The YOLO-style onion detector: model, label assignment, loss, training, inference, mAP."""

from perception.detector import Detections, Detector
from perception.metrics import mean_average_precision
from perception.model import DetectorConfig, DetectorNet

__all__ = ["Detections", "Detector", "DetectorConfig", "DetectorNet", "mean_average_precision"]
