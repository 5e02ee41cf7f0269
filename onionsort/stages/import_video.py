"""Stage ``import``: a video file or a camera becomes a sensor-only session.

A plain video has no step clock, no depth and no ground truth. This stage gives it a step clock,
in one of two ways, and writes one session MCAP (colour and calibration,
:mod:`recordings.session.schema`) that ``perceive``, ``calibrate --no-depth`` and ``learn`` then
use like any other session:

- **fixed clock** (``step_seconds``): a new step every ``step_seconds`` seconds of video time.
  Right when the person works to a rhythm (a line's takt time), and exact for our simulator's
  videos, whose steps last 2 s.
- **perceived changes** (the default): the state classifier reads every window of
  ``frames_per_step`` consecutive frames (colour only); a new step starts where the perceived
  (onion, hand) locations change and the new reading holds for ``debounce`` windows. Windows the
  classifier calls occluded keep the previous reading, so a passer-by does not cut steps. Steps
  nobody can see (during an occlusion, or an action that leaves the picture as it was) still
  take time, so a segment several typical steps long (the median segment) is cut into that
  many equal steps (:func:`recordings.sources.segmentation.split_long_steps`). Measure the
  result with :func:`segmentation_scores`.

Each step keeps ``frames_per_step`` frames spread over it (the first one always), as the state
classifier reads them. A second video of the inspection spot (``inspection``, frame for frame
with the first) gives each step its inspection view, from which perception reads the onion's
class; without it the sorter's prediction is unobserved, and which class goes where cannot be
learned. Intrinsics come from ``intrinsics`` (JSON) or default to a 60-degree
horizontal field of view (:func:`recordings.sources.video.default_intrinsics`).

Example::

    from onionsort.stages import ImportConfig, import_video
    import_video(ImportConfig(out=Path("runs/line.mcap"), video=Path("line.mp4"),
                              step_seconds=2.0))
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from onionsort.configs.import_video import ImportConfig
from onionsort.stages.base import check_output_folder, log_config
from recordings.sources.bags import is_bag

__all__ = ["ImportConfig", "import_video", "list_bag", "perceived_labels", "perceived_segmentation",
           "segmentation_scores"]

logger = logging.getLogger(__name__)

#: Windows classified per batch when segmenting by perceived changes.
_BATCH = 32


def list_bag(path: Path) -> list:
    """The topics of the bag at ``path`` (:class:`recordings.sources.bags.BagTopic`): type, count,
    rate and what the import can use each for."""
    from recordings.sources.bags import Bag

    if not is_bag(path):
        raise ValueError(f"--list lists a bag's topics; {path} is not a ROS bag (a rosbag2 "
                         "folder, its .mcap or .db3 file, or a .bag)")
    with Bag(path) as bag:
        return bag.topics()


def _open(config: ImportConfig):
    from recordings.sources.video import CameraSource, VideoFileSource

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
    from recordings.sources.segmentation import (
        boundaries_from_labels,
        split_long_steps,
        steps_from_boundaries,
    )

    labels = perceived_labels(classifier, colors)
    boundaries = boundaries_from_labels(labels, debounce=debounce)
    return steps_from_boundaries(len(labels), split_long_steps(boundaries, len(labels)))


def _step_of_frame(config: ImportConfig, frames) -> list[int]:
    """The step of each frame (a stream or a list of :class:`SourceFrame`)."""
    if config.step_seconds is None:
        return _perceived(config, (f.color for f in frames))
    return _fixed_clock([f.time_ns for f in frames], config.step_seconds,
                        str(config.video or f"camera {config.camera}"))


def _perceived(config: ImportConfig, colors: Iterable[np.ndarray]) -> list[int]:
    from onionsort.stages.models import PerceptionModels

    classifier = PerceptionModels.load(config.models).classifier
    return perceived_segmentation(classifier, colors, config.debounce)


def _fixed_clock(times: list[int], step_seconds: float, name: str) -> list[int]:
    """Steps of ``step_seconds`` over frames at ``times``; a trailing fragment shorter than
    half a step joins the step before."""
    from recordings.sources.segmentation import fixed_clock

    frame_ns = (times[-1] - times[0]) / (len(times) - 1) if len(times) > 1 else 0
    lasts = (times[-1] - times[0] + frame_ns) / 1e9 if times else 0.0
    if lasts < step_seconds:
        raise ValueError(f"{name} lasts {lasts:.1f} s, shorter than one step of "
                         f"--step-seconds {step_seconds:g}")
    steps = fixed_clock(times, step_seconds)
    # a trailing fragment shorter than half a step is no step: it joins the one before
    fragment = steps.count(steps[-1])
    if steps[-1] > 0 and fragment < 0.5 * steps.count(steps[0]):
        steps[-fragment:] = [steps[-1] - 1] * fragment
    return steps


def import_video(config: ImportConfig):
    """Import the source as one sensor-only session; return the
    :class:`recordings.sources.importer.ImportSummary`.

    A video file is read twice, frame by frame (once to cut it into steps, once to write
    them), so its length is not bounded by memory; a camera's frames are held until it stops
    (``max_seconds``, or Ctrl-C, which ends the recording and imports what was seen).
    """
    from recordings.sources import importer
    from recordings.sources.video import VideoFileSource, default_intrinsics, load_intrinsics

    log_config("import", config)
    check_output_folder(Path(config.out).parent, f"the folder of --out {config.out}")
    if config.is_bag:
        return _import_bag(config)
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
        summary = importer.import_video(
            frames, config.out, frames_per_step=config.frames_per_step, step_of_frame=steps,
            camera_K=K, inspection=views, inspection_K=view_K, metadata=metadata)
    logger.info("%s: %d frames read, %d steps written", config.out, summary.frames_read,
                summary.steps_written)
    return summary


def _import_bag(config: ImportConfig):
    """Import a bag (see :mod:`recordings.sources.bags`); return its
    :class:`recordings.sources.importer.ImportSummary`."""
    from recordings.sources.bags import Bag, BagError, decode_image, steps_from_marks
    from recordings.sources.importer import import_bag

    tolerance = round(config.sync_tolerance * 1e9)
    with Bag(config.video) as bag:
        color = bag.stream(bag.color_topic(config.color_topic, [config.inspection_topic]),
                           "--color-topic", "colour")
        frames = np.arange(len(color.stamps_ns))
        depth, depth_of = None, None
        if config.depth_topic is not None:
            depth = bag.stream(config.depth_topic, "--depth-topic", "depth")
            if (depth.width, depth.height) != (color.width, color.height):
                raise BagError(f"--depth-topic {depth.topic}: depth of {depth.width}x"
                               f"{depth.height} beside colour of {color.width}x{color.height};"
                               " depth must be registered to the colour image, of its size")
            match = depth.nearest(color.stamps_ns, tolerance)
            frames, depth_of = frames[match >= 0], match[match >= 0]
            if not len(frames):
                raise BagError(f"no frame of {color.topic} has depth on {depth.topic} within "
                               f"{config.sync_tolerance:g} s; raise --sync-tolerance")
        times = color.stamps_ns[frames]
        how: dict = {}
        if config.step_topic is not None:
            steps = np.asarray(steps_from_marks(times, bag.marks(config.step_topic)))
            frames, times = frames[steps >= 0], times[steps >= 0]
            if depth_of is not None:
                depth_of = depth_of[steps >= 0]
            steps = steps[steps >= 0].tolist()
            if not steps:
                raise BagError(f"--step-topic {config.step_topic} marks its first step after "
                               f"the last frame of {color.topic}")
            how = {"method": "step topic", "topic": config.step_topic}
        elif config.step_seconds is not None:
            steps = _fixed_clock(times.tolist(), config.step_seconds, bag.name)
            how = {"method": "fixed clock", "step_seconds": config.step_seconds}
        else:
            wanted = {color.topic: set(frames.tolist())}
            steps = _perceived(config, (decode_image(msgtype, msg, color.topic)
                                        for _, _, msgtype, msg in bag.read([color.topic],
                                                                           wanted)))
            how = {"method": "perceived changes", "debounce": config.debounce}
        K, K_from = _bag_intrinsics(bag, config.camera_info_topic, config.intrinsics, color,
                                    "--camera-info-topic")
        view, view_K, view_of, view_K_from = None, None, None, None
        if config.inspection_topic is not None:
            view = bag.stream(config.inspection_topic, "--inspection-topic", "colour")
            view_K, view_K_from = _bag_intrinsics(bag, None, config.inspection_intrinsics, view,
                                                  "--inspection-topic's camera info")
            view_of = view.nearest(times, tolerance)
        topics = {"color": color.topic, "depth": config.depth_topic,
                  "inspection": config.inspection_topic, "intrinsics": K_from,
                  "inspection_intrinsics": view_K_from if view is not None else None}
        summary = import_bag(
            bag, config.out, color=color, frames=frames, step_of_frame=steps,
            frames_per_step=config.frames_per_step, camera_K=K, depth=depth,
            depth_of_frame=depth_of, inspection=view, inspection_of_frame=view_of,
            inspection_K=view_K, metadata={"segmentation": how, "topics": topics})
    logger.info("%s: %d frames read (%d left out), %d steps written", config.out,
                summary.frames_read, summary.frames_dropped, summary.steps_written)
    return summary


def _bag_intrinsics(bag, info_topic: str | None, json_path: Path | None, stream,
                    option: str) -> tuple[np.ndarray, str]:
    """A bag camera's K, and where it came from: ``info_topic``; else ``json_path``; else the
    CameraInfo beside its image topic; else the default for its size. A CameraInfo of another
    size than the images is refused."""
    from recordings.sources.bags import BagError
    from recordings.sources.video import default_intrinsics, load_intrinsics

    if info_topic is None and json_path is not None:
        return load_intrinsics(json_path), str(json_path)
    info_topic = info_topic or bag.camera_info_beside(stream.topic)
    if info_topic is None:
        return default_intrinsics(stream.width, stream.height), "default (60-degree view)"
    K, w, h = bag.intrinsics(info_topic, option)
    if (w, h) != (stream.width, stream.height) and (w, h) != (0, 0):
        raise BagError(f"{option} {info_topic} describes {w}x{h} images; {stream.topic} has "
                       f"{stream.width}x{stream.height}")
    logger.info("%s: intrinsics from %s", stream.topic, info_topic)
    return K, info_topic


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
    from recordings.sources.segmentation import boundary_scores

    def starts(steps):
        return [i for i in range(1, len(steps)) if steps[i] != steps[i - 1]]

    return boundary_scores(starts(predicted_step_of_frame), starts(true_step_of_frame),
                           tolerance=tolerance)
