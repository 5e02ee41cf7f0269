"""Stage ``perceive``: run the perception models on recorded sessions.

Reads only a session's sensor side (colour, depth where there is any, the inspection view, the
step clock) and adds the perception topics to its file (:mod:`recordings.session.perception`),
atomically. The perception record names the models (with their hashes) and whether depth was used,
so ``learn`` can check the calibration was measured for the same models and mode.

Example::

    from onionsort.stages import PerceiveConfig, perceive
    perceive(PerceiveConfig(sessions=(Path("runs/rec/session_000.mcap"),)))
"""

from __future__ import annotations

import functools
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from onionsort.configs.perceive import PerceiveConfig
from onionsort.stages.base import check_output_folder, log_config
from onionsort.stages.models import PerceptionModels
from onionsort.stages.parallel import ParallelOptions, run_pieces

__all__ = ["PerceiveConfig", "PerceivedSession", "perceive", "perceive_session"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class PerceivedSession:
    """What perceiving one session found: its perceived steps, and whether it had depth (else
    the classifier read colour alone)."""

    path: Path
    steps: list
    depth: bool

    @property
    def n_steps(self) -> int:
        return len(self.steps)

    @property
    def n_occluded(self) -> int:
        return sum(s.occluded for s in self.steps)


def perceive(config: PerceiveConfig, models: PerceptionModels | None = None
             ) -> list[PerceivedSession]:
    """Perceive every session of ``config``; return a summary of each.

    Every session is checked first (a readable session, not perceived yet unless
    ``config.replace``, in a folder that takes the rewrite, with steps of the classifier's
    frame count), so a bad one is refused before any model runs or any file changes.
    """
    log_config("perceive", config)
    frames_per_step = _check_sessions(config)
    here = models is not None or (min(config.n_workers, len(config.sessions)) == 1 and \
        config.executor == "local")
    if here:
        if models is None:
            models = PerceptionModels.load_cached(config.models, config.device)
        classifier_frames = models.frames_per_step
    else:  # the workers load the models: this process checks the sessions without torch
        classifier_frames = PerceptionModels.frames_per_step_for_workers(config.models,
                                                                         config.device)
    for path, fps in frames_per_step.items():
        if fps != classifier_frames:
            raise ValueError(_frame_count_error(path, fps, classifier_frames))
    if here:  # one after another, with the models given or loaded here
        options, pieces = ParallelOptions(workers=1), [(models, p) for p in config.sessions]
    else:
        options = config.parallel_options()
        pieces = [((config.models, config.device), p) for p in config.sessions]
    out: list[PerceivedSession | None] = [None] * len(pieces)
    for i, result in run_pieces(functools.partial(_perceive_piece, replace=config.replace,
                                                  batch_size=config.batch_size),
                                pieces, options, names=[str(p) for p in config.sessions],
                                desc="perceive", unit="session"):
        out[i] = result
        logger.info("%s: %d steps, %d called occluded", result.path, result.n_steps,
                    result.n_occluded)
    return out


def _perceive_piece(piece: tuple, *, replace: bool, batch_size: int) -> PerceivedSession:
    """Perceive one session: ``piece`` is ``(models or (folder, device), path)``."""
    models, path = piece
    if not isinstance(models, PerceptionModels):
        models = PerceptionModels.load_cached(*models)
    return perceive_session(models, path, replace=replace, batch_size=batch_size)


def _check_sessions(config: PerceiveConfig) -> dict[Path, int]:
    """Open every session of ``config`` (raising what the reader raises for a file that is not
    a complete session); return the frames per step of each."""
    from recordings.session.reader import open_session

    frames_per_step = {}
    for path in config.sessions:
        session = open_session(path)
        if session.perception_models is not None and not config.replace:
            raise FileExistsError(f"{path} already holds perception topics; pass --replace to "
                                  "perceive it again")
        check_output_folder(Path(path).parent, f"the folder of {path}")
        frames_per_step[Path(path)] = session.frames_per_step
    return frames_per_step


def _frame_count_error(path, frames_per_step: int, classifier_frames: int) -> str:
    return (f"{path}: its steps have {frames_per_step} frames; the state classifier reads "
            f"steps of {classifier_frames}; record it again with `onionsort record "
            f"--frames-per-step {classifier_frames}`")


def perceive_session(models: PerceptionModels, path: Path | str, *, replace: bool = False,
                     batch_size: int = 32) -> PerceivedSession:
    """Run both models on a session's sensor side and add the perception topics to its file.

    Raises
    ------
    ValueError
        If the session's steps do not have the classifier's frame count, or perception finds
        no usable step (none complete, or every one called occluded).
    """
    from recordings.session.perception import add_perception
    from recordings.session.reader import open_session
    from state_abstraction.perceive import perceive_steps

    session = open_session(path)
    if session.frames_per_step != models.frames_per_step:
        raise ValueError(_frame_count_error(path, session.frames_per_step,
                                            models.frames_per_step))
    steps = session.step_frames()
    if not steps:
        raise ValueError(f"{path}: perception found no complete step in {session.n_frames} "
                         "frames; nothing to learn from")
    frames = list(session.frames())
    colors = {f.index: f.color for f in frames}  # each image decoded once
    views = {f.index: f.inspection for f in frames if f.inspection_png is not None}
    inspector = models.inspector()
    perceived = perceive_steps(models.classifier,
                               [([colors[f.index] for f in step],
                                 [f.depth for f in step] if session.has_depth else None,
                                 [views.get(f.index) for f in step]) for step in steps],
                               inspector)
    if all(s.occluded for s in perceived):
        raise ValueError(f"{path}: perception called all {len(perceived)} steps occluded; "
                         "there is no usable step (is the camera blocked?)")
    detections = {}
    order = sorted(colors)
    for i in range(0, len(order), batch_size):
        chunk = order[i:i + batch_size]
        for index, det in zip(chunk, models.detector.detect([colors[k] for k in chunk]),
                              strict=True):
            detections[index] = _rows(det)
    # the inspection's detections as it read the views (each view once), for the topic
    inspection = {k: _rows(d) for k, d in zip(views, inspector.detections(list(views.values())),
                                              strict=True)}
    docs = [{**seen.to_dict(), "frame": step[0].index}
            for seen, step in zip(perceived, steps, strict=True)]
    add_perception(path, docs, detections=detections, inspection=inspection,
                   frame_times={f.index: f.time_ns for f in frames},
                   models={**models.describe(), "depth": session.has_depth,
                           "inspection": session.has_inspection}, replace=replace)
    return PerceivedSession(Path(path), perceived, session.has_depth)


def _rows(det) -> list[tuple]:
    boxes, classes, scores = (np.asarray(det.boxes), np.asarray(det.classes),
                              np.asarray(det.scores))
    return [(*boxes[i].tolist(), int(classes[i]), float(scores[i])) for i in range(len(scores))]
