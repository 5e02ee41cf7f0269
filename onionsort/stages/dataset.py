"""Stage ``dataset``: render labelled frames of the sorting world for perception.

Frames come from whole simulated sessions (the sorter acting on the expert's policy, the
passer-by occluding the camera), split into train, val and test by session: frames of one
session are correlated, so no session appears in two splits. With ``robot_onions`` the Sawyer
also holds onions up to the inspection camera, so the detector learns what the robot will see.
See :mod:`recordings.labels.dataset` for the folder layout and the label records.

Example::

    from onionsort.stages import DatasetConfig, make_dataset
    make_dataset(DatasetConfig(out=Path("runs/data"), frames=300, robot_onions=0))
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace

from onionsort.configs.dataset import DatasetConfig
from onionsort.stages.base import check_output_folder, log_config
from onionsort.stages.parallel import run_pieces

__all__ = ["DatasetConfig", "DatasetSummary", "make_dataset", "split_plan"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class DatasetSummary:
    """What was written: frames, sessions per split, and the robot's inspection views."""

    frames: int
    sessions: dict[str, int]
    robot_views: int


def split_plan(n_sessions: int, val: float, test: float) -> list[str]:
    """The split of each session: train first, then val, then test; each split non-empty."""
    if not (0 < val < 1 and 0 < test < 1 and val + test < 1):
        raise ValueError(f"--val and --test must be in (0, 1) with a sum below 1; got {val}, "
                         f"{test}")
    n_val, n_test = max(1, round(val * n_sessions)), max(1, round(test * n_sessions))
    n_train = n_sessions - n_val - n_test
    if n_train < 1:
        raise ValueError(
            f"{n_sessions} sessions cannot fill three splits; ask for more --frames or fewer "
            "--steps-per-session"
        )
    return ["train"] * n_train + ["val"] * n_val + ["test"] * n_test


def make_dataset(config: DatasetConfig) -> DatasetSummary:
    """Render ``config.frames`` labelled frames into ``config.out``."""
    import numpy as np

    from onionsort import __version__
    from recordings.labels.dataset import DatasetWriter

    log_config("dataset", config)
    if (config.out / "dataset.json").exists():
        raise FileExistsError(f"{config.out} already holds a dataset; choose a new --out")
    check_output_folder(config.out)
    from robot.simulation import INSPECTION_CAMERA, SessionConfig

    levels = config.levels
    width, height = config.inspection_pixels
    inspection = replace(INSPECTION_CAMERA, width=width, height=height)
    session_configs = [SessionConfig(n_steps=config.steps_per_session,
                                     occlusion=config.occlusion,
                                     frames_per_step=config.frames_per_step, difficulty=level,
                                     label_blemishes=config.rot_labels,
                                     randomize_look=config.randomize_look,
                                     inspection=inspection)
                       for level in levels]
    per_session = config.steps_per_session * config.frames_per_step
    n_sessions = math.ceil(config.frames / per_session)
    plan = split_plan(n_sessions, config.val, config.test)
    metadata = {
        "seed": config.seed, "frames": config.frames, "sessions": n_sessions,
        "config": session_configs[0].to_dict(), "software": f"onionsort {__version__}",
        "session_splits": plan,
    }
    if len(levels) > 1:
        metadata["config"]["difficulty"] = [c.difficulty.to_dict() for c in session_configs]
        metadata["session_difficulty"] = [levels[k % len(levels)] for k in range(n_sessions)]
    writer = DatasetWriter(config.out, metadata)
    seeds = np.random.SeedSequence([config.seed, 0x0D47A5E7]).spawn(n_sessions)
    blemish_rate = session_configs[0].blemish_rate  # the sorter's policy: one for all levels
    sessions = [(config.out, plan[k], k, seeds[k], session_configs[k % len(levels)],
                 blemish_rate, min(per_session, config.frames - k * per_session))
                for k in range(n_sessions)]
    views = 0
    try:
        parts = dict(run_pieces(_render_session, sessions, config,
                                names=[f"session {k}" for k in range(n_sessions)],
                                desc="dataset", unit="session"))
        written = 0
        for k in range(n_sessions):  # in the sessions' order, whichever finished first
            written += len(parts[k].records["camera"])
            writer.add_part(plan[k], parts.pop(k))
        if config.robot_onions:
            views = _robot_views(writer, config)
    except BaseException:
        # the labels added so far stay, but no dataset.json: an interrupted dataset never
        # reads as a finished one (a SIGKILL leaves the same)
        writer.flush()
        raise
    writer.close()
    return DatasetSummary(written, {s: plan.count(s) for s in dict.fromkeys(plan)}, views)


def _render_session(piece: tuple):
    """Render one session into its split: ``piece`` is ``(root, split, index, seed,
    session_config, blemish_rate, frames)``; its :class:`recordings.labels.dataset.DatasetPart`."""
    from recordings.labels.dataset import DatasetPart
    from robot.simulation import SortingSession, expert_model

    root, split, k, seed, session_config, blemish_rate, n_frames = piece
    part = DatasetPart(root, split, f"s{k:04d}")
    with SortingSession(session_config, *expert_model(blemish_rate), seed) as session:
        for frame in session.frames():
            if len(part.records["camera"]) == n_frames:
                break
            part.add(frame, session=k, difficulty=session_config.difficulty.name)
    return part


def _robot_views(writer, config: DatasetConfig) -> int:
    """Add the Sawyer's inspection views, line-ups of 10 onions split like the sessions, each
    a piece."""
    import numpy as np

    sizes = [10] * (config.robot_onions // 10) + ([config.robot_onions % 10]
                                                 if config.robot_onions % 10 else [])
    plan = (split_plan(len(sizes), config.val, config.test) if len(sizes) >= 3
            else ["train"] * len(sizes))
    seeds = np.random.SeedSequence([config.seed, 0x5A3E7]).spawn(len(sizes))
    lineups = [(config.out, plan[k], k, sizes[k], seeds[k],
                config.levels[k % len(config.levels)], config.robot_views,
                config.randomize_look)
               for k in range(len(sizes))]
    parts = dict(run_pieces(_render_lineup, lineups, config,
                            names=[f"line-up {k}" for k in range(len(sizes))],
                            desc="robot views", unit="line-up"))
    n = 0
    for k in range(len(sizes)):
        n += len(parts[k].records["inspection"])
        writer.add_part(plan[k], parts.pop(k))
    return n


def _render_lineup(piece: tuple):
    """Render one line-up's inspection views: ``piece`` is ``(root, split, index, size, seed,
    level, views, randomize_look)``; its :class:`recordings.labels.dataset.DatasetPart`."""
    from recordings.labels.dataset import DatasetPart
    from robot.station import robot_inspection_views

    root, split, k, size, seed, level, views, randomize_look = piece
    part = DatasetPart(root, split, f"l{k:04d}")
    for index, view, rgb, labels in robot_inspection_views(size, seed, level,
                                                           inspection_views=views,
                                                           randomize_look=randomize_look):
        part.add_robot_view(rgb, labels, lineup=k, index=index, view=view, difficulty=level)
    return part
