"""Import frames as a sensor-only session (the library side of ``onionsort import``): a video's
or a camera's (:func:`import_video`), or a robot's bag's (:func:`import_bag`).

:func:`import_video` streams the frames of a source (:mod:`recordings.sources.video`, or any
iterable of :class:`~recordings.sources.video.SourceFrame`) into one session MCAP with colour,
calibration and a step clock, and the inspection view when a second source films it: no depth,
no ground truth. :func:`import_bag` writes the frames of a bag's topics
(:mod:`recordings.sources.bags`), with depth where the bag has it. Which step each frame belongs
to is decided beforehand and passed in (``step_of_frame``; see
:mod:`recordings.sources.segmentation` for a fixed clock or perceived changes), so this module
needs no perception model. Of each step it keeps exactly ``frames_per_step`` frames
(:func:`~recordings.sources.segmentation.resample_steps`), written with phases
``0 .. frames_per_step - 1`` and steps numbered ``0 .. T - 1``. Both return an
:class:`ImportSummary`.

The session is written to ``<out>.mcap.partial`` and renamed to ``out_path`` once complete; on
any error (Ctrl-C included) the partial file is removed and the error re-raised, so a failed
import leaves nothing behind.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from recordings.session.writer import SessionWriter
from recordings.sources.bags import Bag, BagError, ImageStream, decode_image, encoded_image
from recordings.sources.segmentation import resample_steps
from recordings.sources.video import SourceFrame

__all__ = ["ImportSummary", "import_bag", "import_video"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class ImportSummary:
    """What an import (:func:`import_video`, :func:`import_bag`) wrote.

    Attributes
    ----------
    path : Path
        The session file.
    source : str
        The source's name (its path, ``camera <i>``, the bag, ...).
    frames_read : int
        Frames the session's steps are made of: all the frames a video or a camera gave, a
        bag's colour frames after synchronisation with depth and after leaving out those before
        the first step mark.
    frames_written : int
        Frames in the session (``steps_written * frames_per_step``; a frame of a short step may
        be written more than once).
    steps_written : int
    frames_per_step : int
    frames_dropped : int
        A bag's colour frames left out: no depth within the tolerance, or before the first step
        mark (0 for a video or a camera).
    depth, inspection : bool
        Whether the session has depth and inspection views.
    """

    path: Path
    source: str
    frames_read: int
    frames_written: int
    steps_written: int
    frames_per_step: int
    frames_dropped: int = 0
    depth: bool = False
    inspection: bool = False

    def __post_init__(self) -> None:
        for name in ("frames_read", "frames_written", "steps_written", "frames_dropped"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0; got {getattr(self, name)}")
        if self.frames_per_step < 1:
            raise ValueError(f"frames_per_step must be >= 1; got {self.frames_per_step}")
        if self.frames_written != self.steps_written * self.frames_per_step:
            raise ValueError(f"frames_written must be steps_written * frames_per_step "
                             f"({self.steps_written * self.frames_per_step}); got "
                             f"{self.frames_written}")


@contextmanager
def _session_file(out_path: Path, name: str, frames_done: Callable[[], int],
                  metadata: dict[str, Any], camera_K: np.ndarray,
                  inspection_K: np.ndarray | None, *, frames_per_step: int,
                  depth: bool) -> Iterator[SessionWriter]:
    """A sensor-only :class:`SessionWriter` on ``<out>.mcap.partial``, renamed to ``out_path``
    once whole; on any error the partial file is removed (logged with ``frames_done()``, how far
    the import of ``name`` got) and the error re-raised."""
    partial = out_path.with_suffix(".mcap.partial")
    if partial.exists():
        logger.warning("%s: replacing a partial file left by an earlier import", partial)
    try:
        with SessionWriter(partial, metadata, camera_K, inspection_K,
                           frames_per_step=frames_per_step, depth=depth, ground_truth=False,
                           overwrite=True) as writer:
            writer.report_interruption = False  # removed on failure: nothing to report
            yield writer
        if out_path.exists():
            raise FileExistsError(f"{out_path} appeared during the import; choose another "
                                  "--out or remove it")
        partial.rename(out_path)
    except BaseException:
        partial.unlink(missing_ok=True)
        logger.info("%s: import into %s failed after %d frames; removed %s", name, out_path,
                    frames_done(), partial.name)
        raise


def import_video(source: Iterable[SourceFrame], out_path: str | Path, *, frames_per_step: int,
                 step_of_frame: Sequence[int], camera_K: np.ndarray,
                 metadata: dict[str, Any] | None = None,
                 inspection: Iterable[SourceFrame] | None = None,
                 inspection_K: np.ndarray | None = None) -> ImportSummary:
    """Write the frames of ``source`` as one sensor-only session.

    The source is read once, frame by frame, holding no more than one frame in memory; only
    the frames :func:`~recordings.sources.segmentation.resample_steps` selects are written. The
    source is not closed (the caller owns it).

    Parameters
    ----------
    source : iterable of SourceFrame
        A :class:`~recordings.sources.video.VideoFileSource`, a
        :class:`~recordings.sources.video.CameraSource`, or frames already read; its ``name``
        attribute (if any) names it in messages and in the session's metadata.
    out_path : path-like
        The session file to create; an existing file is refused.
    frames_per_step : int
        Frames of each written step (the state classifier reads 3).
    step_of_frame : sequence of int, shape (N,)
        The step of each of the source's N frames, non-decreasing (e.g. from
        :func:`~recordings.sources.segmentation.fixed_clock` or
        :func:`~recordings.sources.segmentation.steps_from_boundaries`). The source must give
        exactly N frames.
    camera_K : ndarray of shape (3, 3)
        The camera's intrinsics (:func:`~recordings.sources.video.default_intrinsics` when unknown).
    metadata : dict or None
        Session description (software version, segmentation settings, ...); ``source``,
        ``source_fps`` and ``source_frames`` are added unless given.
    inspection : iterable of SourceFrame or None
        A second camera filming the inspection spot (where the sorter looks at the onion),
        frame for frame with ``source``: its frame at each step's first frame becomes the
        step's inspection view. It must give as many frames as ``source``.
    inspection_K : ndarray of shape (3, 3) or None
        Its intrinsics (required with ``inspection``).

    Returns
    -------
    ImportSummary

    Raises
    ------
    FileExistsError
        If ``out_path`` exists.
    ValueError
        If ``step_of_frame`` covers fewer than ``frames_per_step`` frames or is not
        non-decreasing, if ``camera_K`` is not 3x3, or if the source gives a different number
        of frames than ``step_of_frame`` covers.
    """
    out_path = Path(out_path)
    name = str(getattr(source, "name", "the frames"))
    if isinstance(frames_per_step, bool) or int(frames_per_step) < 1:
        raise ValueError(f"frames_per_step must be >= 1; got {frames_per_step}")
    fps = int(frames_per_step)
    K = np.asarray(camera_K, dtype=float)
    if K.shape != (3, 3) or not np.all(np.isfinite(K)):
        raise ValueError(f"camera_K must be a finite 3x3 matrix; got shape {K.shape}")
    if out_path.exists():
        raise FileExistsError(f"{out_path} exists; choose another --out or remove it")
    n = len(step_of_frame)
    if n < fps:
        raise ValueError(f"{name} has {n} frames; a step needs at least {fps}")
    selected = resample_steps(step_of_frame, fps)
    # source frame index -> [(step, phase), ...] in writing order (a frame may repeat)
    plan: dict[int, list[tuple[int, int]]] = {}
    for step, frames in enumerate(selected):
        for phase, i in enumerate(frames):
            plan.setdefault(i, []).append((step, phase))

    if (inspection is None) != (inspection_K is None):
        raise ValueError("inspection and inspection_K go together; got "
                         f"inspection={'a source' if inspection is not None else None}, "
                         f"inspection_K={'a matrix' if inspection_K is not None else None}")
    views = None if inspection is None else iter(inspection)
    meta = {"source": name, "source_fps": getattr(source, "fps", None), "source_frames": n}
    meta.update(metadata or {})
    read = written = 0
    with _session_file(out_path, name, lambda: read, meta, K, inspection_K, frames_per_step=fps,
                       depth=False) as writer:
        for frame in source:
            if read >= n:
                raise ValueError(f"{name} gave more frames than the {n} step_of_frame "
                                 "covers; segment all of its frames")
            if frame.index != read:
                raise ValueError(f"{name}: frame {read} came with index {frame.index}; "
                                 "frames must be numbered 0, 1, ... in order")
            view = None
            if views is not None:
                view = next(views, None)
                if view is None:
                    raise ValueError(f"the inspection video ended after {read} frames; "
                                     f"it must match {name} frame for frame")
            for step, phase in plan.get(read, ()):
                writer.write_sensor_frame(
                    index=written, step=step, phase=phase, time_ns=int(frame.time_ns),
                    color=frame.color,
                    inspection=view.color if view is not None and phase == 0 else None)
                written += 1
            read += 1
        if read != n:
            raise ValueError(f"{name} ended after {read} frames; step_of_frame covers {n}")
        if views is not None and next(views, None) is not None:
            raise ValueError(f"the inspection video has more frames than the {n} of "
                             f"{name}; it must match frame for frame")
    summary = ImportSummary(path=out_path, source=name, frames_read=read,
                            frames_written=written, steps_written=len(selected),
                            frames_per_step=fps, inspection=inspection is not None)
    logger.info("%s: imported %d of %d frames as %d steps of %d into %s", name, written, read,
                len(selected), fps, out_path)
    return summary


def import_bag(bag: Bag, out_path: str | Path, *, color: ImageStream, frames: np.ndarray,
               step_of_frame: Sequence[int], frames_per_step: int, camera_K: np.ndarray,
               depth: ImageStream | None = None, depth_of_frame: np.ndarray | None = None,
               inspection: ImageStream | None = None,
               inspection_of_frame: np.ndarray | None = None,
               inspection_K: np.ndarray | None = None,
               metadata: dict[str, Any] | None = None) -> ImportSummary:
    """Write the kept frames of ``bag`` as one sensor-only session at ``out_path``.

    Parameters
    ----------
    bag : Bag
    out_path : path-like
        The session file; written to ``<out>.mcap.partial`` and renamed once whole (an
        existing file is refused, a failed import leaves nothing).
    color : ImageStream
        The colour topic.
    frames : ndarray of int, shape (N,)
        The colour messages the session is made of (indices on the topic), in time order.
    step_of_frame : sequence of int, shape (N,)
        The step of each, non-decreasing.
    frames_per_step : int
    camera_K : ndarray of shape (3, 3)
    depth, depth_of_frame : ImageStream and ndarray of int, shape (N,), or None
        The depth topic and the depth message of each frame.
    inspection, inspection_of_frame, inspection_K
        The inspection topic, the view of each frame (its message, -1: none; shape (N,)), and
        the view's intrinsics.
    metadata : dict or None
        Added to the session's description.
    """
    out_path = Path(out_path)
    if out_path.exists():
        raise FileExistsError(f"{out_path} exists; choose another --out or remove it")
    selected = resample_steps(step_of_frame, frames_per_step)
    sizes = np.bincount(np.unique(np.asarray(step_of_frame), return_inverse=True)[1])
    if np.any(sizes < frames_per_step):
        logger.warning("%s: %d of %d steps hold fewer than %d frames; their frames are "
                       "repeated to make %d each", bag.name, int(np.sum(sizes < frames_per_step)),
                       len(sizes), frames_per_step, frames_per_step)
    times = color.stamps_ns[frames]
    t0 = int(times.min())
    # the session's frames in order: (step, phase, colour message, depth message, view message)
    plan = []
    for step, picks in enumerate(selected):
        for phase, i in enumerate(picks):
            plan.append((step, phase, int(frames[i]), int(times[i]) - t0,
                         int(depth_of_frame[i]) if depth_of_frame is not None else -1,
                         int(inspection_of_frame[i]) if inspection_of_frame is not None
                         else -1))
    wanted: dict[str, set[int]] = {color.topic: {p[2] for p in plan}}
    if depth is not None:
        wanted.setdefault(depth.topic, set()).update(p[4] for p in plan)
    if inspection is not None:
        wanted.setdefault(inspection.topic, set()).update(p[5] for p in plan if p[5] >= 0)
    last_use: dict[tuple[str, int], int] = {}
    for n, (_, _, c, _, d, v) in enumerate(plan):
        last_use[(color.topic, c)] = n
        if d >= 0:
            last_use[(depth.topic, d)] = n
        if v >= 0:
            last_use[(inspection.topic, v)] = n

    meta = {"source": bag.name, "source_frames": len(frames)}
    meta.update(metadata or {})
    held: dict[tuple[str, int], Any] = {}
    written = 0
    color_size: tuple[int, int] | None = None
    with _session_file(out_path, bag.name, lambda: written, meta, camera_K, inspection_K,
                       frames_per_step=frames_per_step, depth=depth is not None) as writer:
        def write_ready() -> None:
            nonlocal written, color_size
            while written < len(plan):
                step, phase, c, t, d, v = plan[written]
                keys = [(color.topic, c)] + ([(depth.topic, d)] if d >= 0 else []) + (
                    [(inspection.topic, v)] if v >= 0 else [])
                if any(k not in held for k in keys):
                    return
                image = held[keys[0]]
                size = (image.width, image.height)
                color_size = color_size or size
                if size != color_size:
                    raise BagError(f"{color.topic}: image {c} is {size[0]}x{size[1]}, the "
                                   f"first {color_size[0]}x{color_size[1]}; a session's "
                                   "frames share one size")
                metres = held[keys[1]] if d >= 0 else None
                if metres is not None and metres.shape != (size[1], size[0]):
                    raise BagError(f"--depth-topic {depth.topic}: depth of "
                                   f"{metres.shape[1]}x{metres.shape[0]} beside colour of "
                                   f"{size[0]}x{size[1]}; depth must be registered to the "
                                   "colour image, of its size")
                view = held[keys[-1]] if v >= 0 else None
                writer.write_sensor_frame(index=written, step=step, phase=phase, time_ns=t,
                                          color=image, depth=metres, inspection=view)
                for k in keys:
                    if last_use[k] == written:
                        del held[k]
                written += 1

        for topic, i, msgtype, msg in bag.read(list(wanted), wanted):
            if topic == color.topic or (inspection is not None
                                        and topic == inspection.topic):
                held[(topic, i)] = encoded_image(msgtype, msg, topic)
            else:
                held[(topic, i)] = decode_image(msgtype, msg, topic)
            write_ready()
        if written != len(plan):
            raise BagError(f"{bag.name}: {len(plan) - written} of the session's frames "
                           "could not be read back; the bag changed while it was read")
    return ImportSummary(path=out_path, source=bag.name, frames_read=len(frames),
                         frames_written=written, steps_written=len(selected),
                         frames_per_step=frames_per_step,
                         frames_dropped=len(color.stamps_ns) - len(frames),
                         depth=depth is not None, inspection=inspection is not None)
