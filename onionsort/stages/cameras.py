"""Other cameras for a dataset: each session and line-up seen through a camera of its own.

What the evaluation through other cameras measures through and what the detector can be
trained through (:mod:`perception.camera_shift` draws each camera)."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from onionsort.configs.calibrate import check_camera_shift

__all__ = ["SessionCameras"]


@dataclass(frozen=True)
class SessionCameras:
    """A dataset seen through other cameras: each session and each robot line-up through a
    camera of its own, ``CameraShift.draw((seed, kind, index))`` (kind 0 a session, 1 a
    line-up; :mod:`perception.camera_shift`), on its colour images and inspection views alike;
    with ``one_camera``, every image through the one camera ``CameraShift.draw(seed)``, as a
    lab with one camera would take them. An :data:`recordings.labels.dataset.ImageMap`."""

    seed: int
    one_camera: bool = False

    def __post_init__(self) -> None:
        check_camera_shift(self.seed)

    def camera(self, record: dict):
        """The camera of the session or line-up ``record`` belongs to."""
        if self.one_camera:
            return _camera(int(self.seed), None, None)
        robot = record.get("source", "human") == "robot"
        return _camera(int(self.seed), int(robot),
                       int(record["lineup"] if robot else record["session"]))

    def __call__(self, image: np.ndarray, record: dict) -> np.ndarray:
        return self.camera(record).apply(image)


@functools.lru_cache(maxsize=4096)
def _camera(seed: int, kind: int | None, index: int | None):
    from perception.camera_shift import CameraShift

    return CameraShift.draw(seed if kind is None else (seed, kind, index))
