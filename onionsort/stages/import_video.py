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

import contextlib
import logging
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from onionsort.stages.base import check_output_folder, log_config

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
    A window called occluded (``OCCLUDED_THRESHOLD``) keeps the previous window's reading.
    Frames are read as a stream: at most ``fps`` frames and one batch of windows are held.
    """
    from collections import deque

    from state_abstraction.classifier import OCCLUDED_THRESHOLD, step_input

    fps = classifier.config.frames
    labels: list[tuple[int, int]] = []
    batch: list[np.ndarray] = []

    def classify() -> None:
        probs = classifier.predict(np.stack(batch))
        for onion, hand, p_occluded in zip(probs["onion"].argmax(1),
                                           probs["end_effector"].argmax(1),
                                           probs["occluded"][:, 1], strict=True):
            occluded = p_occluded >= OCCLUDED_THRESHOLD
            labels.append(labels[-1] if occluded and labels else (int(onion), int(hand)))
        batch.clear()

    def window(frames) -> None:
        batch.append(step_input(list(frames), None, classifier.config))
        if len(batch) == _BATCH:
            classify()

    recent: deque[np.ndarray] = deque(maxlen=fps)
    for color in colors:
        recent.append(np.asarray(color))
        if len(recent) == fps:
            window(recent)
    n_windows = len(labels) + len(batch)
    tail = list(recent)[1:] if n_windows else list(recent)  # windows not started yet
    for i in range(len(tail)):
        frames = tail[i:]
        window(frames + [frames[-1]] * (fps - len(frames)))
    if batch:
        classify()
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
    """The step of each frame (a stream or a list of :class:`SourceFrame`)."""
    from recordings.segmentation import fixed_clock

    if config.step_seconds is None:
        from onionsort.stages.models import PerceptionModels

        classifier = PerceptionModels.load(config.models).classifier
        return perceived_segmentation(classifier, (f.color for f in frames), config.debounce)
    times = [f.time_ns for f in frames]
    frame_ns = (times[-1] - times[0]) / (len(times) - 1) if len(times) > 1 else 0
    lasts = (times[-1] - times[0] + frame_ns) / 1e9 if times else 0.0
    if lasts < config.step_seconds:
        raise ValueError(f"{config.video or f'camera {config.camera}'} lasts {lasts:.1f} s, "
                         f"shorter than one step of --step-seconds {config.step_seconds:g}")
    steps = fixed_clock(times, config.step_seconds)
    # a trailing fragment shorter than half a step is no step: it joins the one before
    fragment = steps.count(steps[-1])
    if steps[-1] > 0 and fragment < 0.5 * steps.count(steps[0]):
        steps[-fragment:] = [steps[-1] - 1] * fragment
    return steps


def import_video(config: ImportConfig):
    """Import the source as one sensor-only session; return the
    :class:`recordings.video_import.ImportSummary`.

    A video file is read twice, frame by frame (once to cut it into steps, once to write
    them), so its length is not bounded by memory; a camera's frames are held until it stops
    (``max_seconds``, or Ctrl-C, which ends the recording and imports what was seen).
    """
    from recordings import video_import
    from recordings.sources import VideoFileSource, default_intrinsics, load_intrinsics

    log_config("import", config)
    check_output_folder(Path(config.out).parent, f"the folder of --out {config.out}")
    with _open(config) as source:
        name = source.name
        K = (load_intrinsics(config.intrinsics) if config.intrinsics is not None
             else default_intrinsics(source.width, source.height))
        if config.video is None:
            frames = _read_camera(source)
            steps = _step_of_frame(config, frames)
        else:
            steps = _step_of_frame(config, source)
    metadata = {"source": name, "segmentation": (
        {"method": "fixed clock", "step_seconds": config.step_seconds}
        if config.step_seconds is not None
        else {"method": "perceived changes", "debounce": config.debounce})}
    with contextlib.ExitStack() as stack:
        if config.video is not None:
            frames = stack.enter_context(VideoFileSource(config.video))
        views, view_K = None, None
        if config.inspection is not None:
            views = stack.enter_context(VideoFileSource(config.inspection))
            view_K = (load_intrinsics(config.inspection_intrinsics)
                      if config.inspection_intrinsics is not None
                      else default_intrinsics(views.width, views.height))
        summary = video_import.import_video(
            frames, config.out, frames_per_step=config.frames_per_step, step_of_frame=steps,
            camera_K=K, inspection=views, inspection_K=view_K, metadata=metadata)
    logger.info("%s: %d frames read, %d steps written", config.out, summary.frames_read,
                summary.steps_written)
    return summary


def _read_camera(source) -> list:
    frames = []
    try:
        for frame in source:
            frames.append(frame)
    except KeyboardInterrupt:
        logger.warning("%s: stopped by Ctrl-C after %d frames; importing them", source.name,
                       len(frames))
    return frames


def segmentation_scores(predicted_step_of_frame, true_step_of_frame, tolerance: int = 1) -> dict:
    """Step-boundary precision and recall of a segmentation against the truth, within
    ``tolerance`` frames (frame 0, a boundary by definition, is not scored)."""
    from recordings.segmentation import boundary_scores

    def starts(steps):
        return [i for i in range(1, len(steps)) if steps[i] != steps[i - 1]]

    return boundary_scores(starts(predicted_step_of_frame), starts(true_step_of_frame),
                           tolerance=tolerance)
