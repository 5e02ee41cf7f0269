"""Stage ``dataset``: render labelled frames of the sorting world for perception.

Frames come from whole simulated sessions (the sorter acting on the expert's policy, the
passer-by occluding the camera), split into train, val and test by session: frames of one
session are correlated, so no session appears in two splits. With ``robot_onions`` the Sawyer
also holds onions up to the inspection camera, so the detector learns what the robot will see.
See :mod:`recordings.dataset` for the folder layout and the label records.

Example::

    from onionsort.stages import DatasetConfig, make_dataset
    make_dataset(DatasetConfig(out=Path("runs/data"), frames=300, robot_onions=0))
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path

from onionsort.stages.base import check_difficulty, check_output_folder, log_config
from onionsort.stages.parallel import ParallelOptions, run_pieces

__all__ = ["DatasetConfig", "DatasetSummary", "make_dataset", "split_plan"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class DatasetConfig(ParallelOptions):
    """What to render.

    Attributes
    ----------
    out : Path
        A new dataset folder (an existing dataset is never overwritten).
    frames : int
        Camera frames in all.
    seed : int
    occlusion : float
        Probability that the passer-by occludes a step (0.3: the classifier must see many).
    steps_per_session, frames_per_step : int
    val, test : float
        Shares of sessions for the val and test splits.
    robot_onions : int
        Onions the Sawyer holds up to its inspection camera, in line-ups of 10 split like the
        sessions; 0 for none.
    robot_views : int
        Views of each of them (:func:`robot.station.inspection_poses`).
    rot_labels : bool
        Measure the rot each inspection view shows (the inspection classifier's labels; one
        more render of each view). Calibration needs none.
    difficulty : str
        Perception difficulty, a level of ``robot.difficulty.DIFFICULTY_LEVELS`` (``clean``:
        today's world), or several joined by commas (``clean,realistic,paper,hard``): a mix,
        whose sessions and robot line-ups take the levels in turn.
    randomize_look : bool
        Each session and line-up draws its look from its seed (:mod:`robot.look`: light,
        surface colours, the cameras' exposure and white balance): training data that spans
        cameras. The levels stay as they are; the look is a knob beside them.
    executor, workers, ray_address
        Where the sessions and the line-ups are rendered
        (:class:`~onionsort.stages.parallel.ParallelOptions`): each is a piece, rendered from
        its own seed into images named after it (``s0003_0012.png``, ``l0001_0004.png``).
    """

    out: Path
    frames: int = 3000
    seed: int = 0
    occlusion: float = 0.3
    steps_per_session: int = 20
    frames_per_step: int = 3
    val: float = 0.15
    test: float = 0.15
    robot_onions: int = 120
    difficulty: str = "clean"
    robot_views: int = 8
    rot_labels: bool = True
    randomize_look: bool = False

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "out", Path(self.out))
        for level in self.levels:
            check_difficulty(level)
        if self.frames < 1:
            raise ValueError(f"frames must be >= 1; got {self.frames}")
        if self.robot_onions < 0:
            raise ValueError(f"robot_onions must be >= 0; got {self.robot_onions}")
        if self.robot_views < 1:
            raise ValueError(f"robot_views must be >= 1; got {self.robot_views}")

    @property
    def levels(self) -> list[str]:
        """The difficulty levels, in the order sessions and line-ups take them."""
        return [level.strip() for level in self.difficulty.split(",")]


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
    from recordings.dataset import DatasetWriter

    log_config("dataset", config)
    if (config.out / "dataset.json").exists():
        raise FileExistsError(f"{config.out} already holds a dataset; choose a new --out")
    check_output_folder(config.out)
    from robot.simulation import SessionConfig

    levels = config.levels
    session_configs = [SessionConfig(n_steps=config.steps_per_session,
                                     occlusion=config.occlusion,
                                     frames_per_step=config.frames_per_step, difficulty=level,
                                     label_blemishes=config.rot_labels,
                                     randomize_look=config.randomize_look)
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
    session_config, blemish_rate, frames)``; its :class:`recordings.dataset.DatasetPart`."""
    from recordings.dataset import DatasetPart
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
    level, views, randomize_look)``; its :class:`recordings.dataset.DatasetPart`."""
    from recordings.dataset import DatasetPart
    from robot.station import robot_inspection_views

    root, split, k, size, seed, level, views, randomize_look = piece
    part = DatasetPart(root, split, f"l{k:04d}")
    for index, view, rgb, labels in robot_inspection_views(size, seed, level,
                                                           inspection_views=views,
                                                           randomize_look=randomize_look):
        part.add_robot_view(rgb, labels, lineup=k, index=index, view=view, difficulty=level)
    return part
