"""The perception models a stage runs (:mod:`onionsort.perception_models`, which loads them
without the stages: a robot's own process imports it alone), as the stages name them."""

from onionsort.perception_models import (
    CALIBRATION_FILE,
    CLASSIFIER_FILE,
    DEFAULT_MODELS,
    DETECTOR_FILE,
    HASH_KEYS,
    INSPECTION_FILE,
    ROBOT_DETECTOR_FILE,
    ROBOT_FUSION_FILE,
    ROBOT_INSPECTION_FILE,
    PerceptionModels,
    model_mismatch,
    read_fused_calibration,
)

__all__ = [
    "CALIBRATION_FILE",
    "CLASSIFIER_FILE",
    "DEFAULT_MODELS",
    "DETECTOR_FILE",
    "HASH_KEYS",
    "INSPECTION_FILE",
    "ROBOT_DETECTOR_FILE",
    "ROBOT_FUSION_FILE",
    "ROBOT_INSPECTION_FILE",
    "PerceptionModels",
    "model_mismatch",
    "read_fused_calibration",
]
