"""The YOLO-style onion detector: model, label assignment, loss, training, inference, mAP.

The names below load on first use, so that importing a torch-free submodule (``perception.fusion``,
which a stage's config reads to check its fusion rule) does not load torch.
"""

from __future__ import annotations

import importlib

__all__ = ["Detections", "Detector", "DetectorConfig", "DetectorNet", "mean_average_precision"]

_WHERE = {"Detections": "perception.detector", "Detector": "perception.detector",
          "DetectorConfig": "perception.model", "DetectorNet": "perception.model",
          "mean_average_precision": "perception.metrics"}


def __getattr__(name: str):
    if name in _WHERE:
        value = getattr(importlib.import_module(_WHERE[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'perception' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *__all__])
