"""Stage ``import``: a video file or a camera becomes a sensor-only session.

A plain video has no step clock, no depth and no ground truth. This stage gives it a step clock,
in one of two ways, and writes one session MCAP (colour and calibration, :mod:`recordings.schema`)
that ``perceive``, ``calibrate --no-depth`` and ``learn`` then use like any other session:

- **fixed clock** (``step_seconds``): a new step every ``step_seconds`` seconds of video time.
  Right when the person works to a rhythm (a line's takt time), and exact for our simulator's
  videos, whose steps last 2 s.
- **perceived changes** (the default): the state classifier reads every window of
  ``frames_per_step`` consecutive frames (colour only); a new step starts where the perceived
  (onion, hand) locations change and the new reading holds for ``debounce`` windows. Windows the
  classifier calls occluded keep the previous reading, so a passer-by does not cut steps. Steps
  nobody can see (during an occlusion, or an action that leaves the picture as it was) still
  take time, so a segment several typical steps long (the median segment) is cut into that
  many equal steps (:func:`recordings.segmentation.split_long_steps`). Measure the result with
  :func:`segmentation_scores`.

Each step keeps ``frames_per_step`` frames spread over it (the first one always), as the state
classifier reads them. A second video of the inspection spot (``inspection``, frame for frame
with the first) gives each step its inspection view, from which perception reads the onion's
class; without it the sorter's prediction is unobserved, and which class goes where cannot be
learned. Intrinsics come from ``intrinsics`` (JSON) or default to a 60-degree
horizontal field of view (:func:`recordings.sources.default_intrinsics`).

Example::

    from onionsort.stages import ImportConfig, import_video
    import_video(ImportConfig(out=Path("runs/line.mcap"), video=Path("line.mp4"),
                              step_seconds=2.0))
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from onionsort.stages.base import log_config

__all__ = ["ImportConfig", "import_video", "perceived_labels", "perceived_segmentation",
           "segmentation_scores"]

logger = logging.getLogger(__name__)

#: Windows classified per batch when segmenting by perceived changes.
_BATCH = 32


@dataclass(frozen=True)
class ImportConfig:
    """Where the frames come from, how they are cut into steps, and where the session goes.

    Attributes
    ----------
    out : Path
        The session file to create (``.mcap``); an existing file is refused.
    video : Path or None
        A video file (any container and codec OpenCV reads).
    camera : int or None
        A camera index for ``cv2.VideoCapture``; exactly one of ``video`` and ``camera``.
    step_seconds : float or None
        Fixed clock: a step every so many seconds. None: segment by perceived changes.
    debounce : int
        Windows a new perceived reading must hold before it starts a step.
    frames_per_step : int
        Frames kept per step (the state classifier reads 3).
    intrinsics : Path or None
        JSON intrinsics (``{"K": 3x3}`` or ``{"fx", "fy", "cx", "cy"}``).
    models : Path or None
        Perception models for the perceived-change segmentation (None: the shipped ones).
    max_seconds : float
        How long to record from a camera.
    inspection : Path or None
        A video of the inspection spot, frame for frame with ``video``.
    inspection_intrinsics : Path or None
        Its intrinsics JSON (default: a 60-degree horizontal view).
    """

    out: Path
    video: Path | None = None
    camera: int | None = None
    step_seconds: float | None = None
    debounce: int = 2
    frames_per_step: int = 3
    intrinsics: Path | None = None
    models: Path | None = None
    max_seconds: float = 60.0
    inspection: Path | None = None
    inspection_intrinsics: Path | None = None

    def __post_init__(self) -> None:
        if (self.video is None) == (self.camera is None):
            raise ValueError("give exactly one source: a video file or --camera INDEX; got "
                             f"video={self.video}, camera={self.camera}")
        if self.step_seconds is not None and not self.step_seconds > 0:
            raise ValueError(f"step_seconds must be > 0; got {self.step_seconds}")
        if self.debounce < 1:
            raise ValueError(f"debounce must be >= 1; got {self.debounce}")
        if self.frames_per_step < 1:
            raise ValueError(f"frames_per_step must be >= 1; got {self.frames_per_step}")
        if not self.max_seconds > 0:
            raise ValueError(f"max_seconds must be > 0; got {self.max_seconds}")
        if self.inspection is not None and self.video is None:
            raise ValueError("--inspection VIDEO goes with a video file, not --camera")
        if Path(self.out).exists():
            raise FileExistsError(f"{self.out} exists; choose another --out")


def _open(config: ImportConfig):
    from recordings.sources import CameraSource, VideoFileSource

    if config.video is not None:
        return VideoFileSource(config.video)
    return CameraSource(config.camera, max_seconds=config.max_seconds)


def perceived_labels(classifier, colors: Iterable[np.ndarray]) -> list[tuple[int, int]]:
    """The perceived (onion, hand) locations of each frame's window, colour only.

    Window ``i`` is frames ``i .. i + fps - 1`` (the last frames repeat at the end), read by the
    state classifier as one step; its location heads say what the window's first frame shows.
    A window called occluded keeps the previous window's reading.
    """
    from state_abstraction.classifier import step_input

    fps = classifier.config.frames
    frames = [np.asarray(c) for c in colors]
    labels: list[tuple[int, int]] = []
    for start in range(0, len(frames), _BATCH):
        x = np.stack([step_input([frames[min(i + k, len(frames) - 1)] for k in range(fps)],
                                 None, classifier.config)
                      for i in range(start, min(start + _BATCH, len(frames)))])
        probs = classifier.predict(x)
        for onion, hand, occluded in zip(probs["onion"].argmax(1), probs["end_effector"].argmax(1),
                                         probs["occluded"][:, 1] >= 0.5, strict=True):
            labels.append(labels[-1] if occluded and labels else (int(onion), int(hand)))
    return labels


def perceived_segmentation(classifier, colors: Iterable[np.ndarray], debounce: int) -> list[int]:
    """The step of each frame from perceived changes, long segments cut at the typical step
    length (see the module docstring)."""
    from recordings.segmentation import (
        boundaries_from_labels,
        split_long_steps,
        steps_from_boundaries,
    )

    labels = perceived_labels(classifier, colors)
    boundaries = boundaries_from_labels(labels, debounce=debounce)
    return steps_from_boundaries(len(labels), split_long_steps(boundaries, len(labels)))


def _step_of_frame(config: ImportConfig, frames) -> list[int]:
    from recordings.segmentation import fixed_clock

    if config.step_seconds is not None:
        times = [f.time_ns for f in frames]
        frame_ns = (times[-1] - times[0]) / (len(times) - 1) if len(times) > 1 else 0
        lasts = (times[-1] - times[0] + frame_ns) / 1e9 if times else 0.0
        if lasts < config.step_seconds:
            raise ValueError(f"{config.video or f'camera {config.camera}'} lasts {lasts:.1f} s, "
                             f"shorter than one step of --step-seconds {config.step_seconds:g}")
        return fixed_clock(times, config.step_seconds)
    from onionsort.stages.models import PerceptionModels

    classifier = PerceptionModels.load(config.models).classifier
    return perceived_segmentation(classifier, (f.color for f in frames), config.debounce)


def import_video(config: ImportConfig):
    """Import the source as one sensor-only session; return the
    :class:`recordings.video_import.ImportSummary`."""
    from recordings import video_import
    from recordings.sources import default_intrinsics, load_intrinsics

    log_config("import", config)
    with _open(config) as source:
        frames = list(source)  # a video is read twice otherwise; a camera cannot be
        name = source.name
        K = (load_intrinsics(config.intrinsics) if config.intrinsics is not None
             else default_intrinsics(source.width, source.height))
    steps = _step_of_frame(config, frames)
    views, view_K = None, None
    if config.inspection is not None:
        from recordings.sources import VideoFileSource

        with VideoFileSource(config.inspection) as view_source:
            views = list(view_source)
            view_K = (load_intrinsics(config.inspection_intrinsics)
                      if config.inspection_intrinsics is not None
                      else default_intrinsics(view_source.width, view_source.height))
        if len(views) != len(frames):
            raise ValueError(f"{config.inspection} has {len(views)} frames and {name} has "
                             f"{len(frames)}; the inspection video must match frame for frame")
    summary = video_import.import_video(
        frames, config.out, frames_per_step=config.frames_per_step, step_of_frame=steps,
        camera_K=K, inspection=views, inspection_K=view_K,
        metadata={"source": name, "segmentation": (
            {"method": "fixed clock", "step_seconds": config.step_seconds}
            if config.step_seconds is not None
            else {"method": "perceived changes", "debounce": config.debounce})})
    logger.info("%s: %d frames read, %d steps written", config.out, summary.frames_read,
                summary.steps_written)
    return summary


def segmentation_scores(predicted_step_of_frame, true_step_of_frame, tolerance: int = 1) -> dict:
    """Step-boundary precision and recall of a segmentation against the truth, within
    ``tolerance`` frames (frame 0, a boundary by definition, is not scored)."""
    from recordings.segmentation import boundary_scores

    def starts(steps):
        return [i for i in range(1, len(steps)) if steps[i] != steps[i - 1]]

    return boundary_scores(starts(predicted_step_of_frame), starts(true_step_of_frame),
                           tolerance=tolerance)
