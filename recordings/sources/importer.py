"""Import a video or a camera's frames as a sensor-only session (the library side of
``onionsort import``).

:func:`import_video` streams the frames of a source (:mod:`recordings.sources.video`, or any
iterable of :class:`~recordings.sources.video.SourceFrame`) into one session MCAP with colour,
calibration and a step clock, and the inspection view when a second source films it: no depth, no
ground truth. Which step each source frame
belongs to is decided beforehand and passed in (``step_of_frame``; see
:mod:`recordings.sources.segmentation` for a fixed clock or perceived changes), so this module needs
no perception model. Of each step it keeps exactly ``frames_per_step`` frames
(:func:`~recordings.sources.segmentation.resample_steps`), written with phases
``0 .. frames_per_step - 1`` and steps numbered ``0 .. T - 1``.

The session is written to ``<out>.mcap.partial`` and renamed to ``out_path`` once complete; on
any error (Ctrl-C included) the partial file is removed and the error re-raised, so a failed
import leaves nothing behind.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from recordings.session.writer import SessionWriter
from recordings.sources.segmentation import resample_steps
from recordings.sources.video import SourceFrame

__all__ = ["ImportSummary", "import_video"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class ImportSummary:
    """What :func:`import_video` wrote.

    Attributes
    ----------
    path : Path
        The session file.
    source : str
        The source's name (its path, ``camera <i>``, ...).
    frames_read : int
        Frames the source gave.
    frames_written : int
        Frames in the session (``steps_written * frames_per_step``; a frame of a short step may
        be written more than once).
    steps_written : int
    frames_per_step : int
    """

    path: Path
    source: str
    frames_read: int
    frames_written: int
    steps_written: int
    frames_per_step: int

    def __post_init__(self) -> None:
        for name in ("frames_read", "frames_written", "steps_written"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0; got {getattr(self, name)}")
        if self.frames_per_step < 1:
            raise ValueError(f"frames_per_step must be >= 1; got {self.frames_per_step}")
        if self.frames_written != self.steps_written * self.frames_per_step:
            raise ValueError(f"frames_written must be steps_written * frames_per_step "
                             f"({self.steps_written * self.frames_per_step}); got "
                             f"{self.frames_written}")


def _partial_path(out_path: Path) -> Path:
    return out_path.with_suffix(".mcap.partial")


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
    partial = _partial_path(out_path)
    if partial.exists():
        logger.warning("%s: replacing a partial file left by an earlier import", partial)
    read = written = 0
    try:
        with SessionWriter(partial, meta, K, inspection_K, frames_per_step=fps, depth=False,
                           ground_truth=False, overwrite=True) as writer:
            writer.report_interruption = False  # removed on failure: nothing to report
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
        if out_path.exists():
            raise FileExistsError(f"{out_path} appeared during the import; choose another "
                                  "--out or remove it")
        partial.rename(out_path)
    except BaseException:
        partial.unlink(missing_ok=True)
        logger.info("%s: import into %s failed after %d frames; removed %s", name, out_path,
                    read, partial.name)
        raise
    summary = ImportSummary(path=out_path, source=name, frames_read=read,
                            frames_written=written, steps_written=len(selected),
                            frames_per_step=fps)
    logger.info("%s: imported %d of %d frames as %d steps of %d into %s", name, written, read,
                len(selected), fps, out_path)
    return summary
