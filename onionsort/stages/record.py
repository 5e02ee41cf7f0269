"""Stage ``record``: simulate sorting sessions and write one MCAP file per session.

A simulated person sorts onions on a conveyor, acting on the expert's Boltzmann policy, while a
passer-by sometimes walks through the camera's view. Each session is written to
``OUT/session_NNN.mcap`` frame by frame: its sensor side (colour, depth, calibration, the step
clock, the inspection view) and its ground truth (see :mod:`recordings.schema`). Ctrl-C or
SIGTERM finishes the open file with status ``interrupted``.

Example::

    from onionsort.stages import RecordConfig, record
    paths = record(RecordConfig(out=Path("runs/rec"), sessions=2, steps_per_session=10))
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

from onionsort.stages.base import check_difficulty, log_config, output_folder

__all__ = ["RecordConfig", "record"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class RecordConfig:
    """How many sessions to simulate, how, and where to write them.

    Attributes
    ----------
    out : Path
        Folder for the ``.mcap`` files.
    sessions : int
    seed : int
        Root seed; sessions are reproducible from it.
    occlusion : float
        Probability that the passer-by occludes a step.
    steps_per_session, frames_per_step : int
    width, height : int
        Main camera resolution.
    overwrite : bool
        Replace existing session files in ``out``.
    rerun : Path, str or None
        Also log every session to Rerun: an ``.rrd`` path, ``"spawn"``, or a viewer URL.
    difficulty : str
        Perception difficulty, a level of ``robot.difficulty.DIFFICULTY_LEVELS`` (``clean``:
        today's world).
    """

    out: Path
    sessions: int = 12
    seed: int = 0
    occlusion: float = 0.2
    steps_per_session: int = 20
    frames_per_step: int = 3
    width: int = 320
    height: int = 240
    overwrite: bool = False
    rerun: Path | str | None = None
    difficulty: str = "clean"

    def __post_init__(self) -> None:
        check_difficulty(self.difficulty)
        for name in ("sessions", "steps_per_session", "frames_per_step"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1; got {getattr(self, name)}")
        if not 0.0 <= self.occlusion <= 1.0:
            raise ValueError(f"occlusion must be in [0, 1]; got {self.occlusion}")
        if min(self.width, self.height) < 8:
            raise ValueError(f"width and height must be >= 8; got {self.width}x{self.height}")


def record(config: RecordConfig) -> list[Path]:
    """Record ``config.sessions`` sessions; return their paths."""
    log_config("record", config)
    with output_folder(config.out) as out:  # checked before anything is imported or rendered
        paths = [out / f"session_{i:03d}.mcap" for i in range(config.sessions)]
        existing = [p for p in paths if p.exists()]
        if existing and not config.overwrite:
            raise FileExistsError(f"{existing[0]} exists ({len(existing)} session files in "
                                  f"{out}); pass --overwrite or choose another --out")
        _record_sessions(config, paths)
    return paths


def _record_sessions(config: RecordConfig, paths: list[Path]) -> None:
    import dataclasses
    import platform
    import signal

    import numpy as np
    import pybullet
    from tqdm import tqdm

    from onionsort import __version__
    from recordings import SessionWriter, open_session
    from robot.camera import CameraSpec, intrinsics
    from robot.simulation import SessionConfig, SortingSession, expert_model

    session_config = SessionConfig(
        n_steps=config.steps_per_session, occlusion=config.occlusion,
        frames_per_step=config.frames_per_step,
        camera=dataclasses.replace(CameraSpec(), width=config.width, height=config.height),
        difficulty=config.difficulty,
    )
    policy, initial = expert_model(session_config.blemish_rate)
    seeds = np.random.SeedSequence(config.seed).spawn(config.sessions)
    rerun_logger = None
    if config.rerun is not None:
        from recordings.rerun import SessionLogger

        rerun_logger = SessionLogger(config.rerun)

    def _terminate(signum, _frame):  # finish the open file on SIGTERM as on Ctrl-C
        raise KeyboardInterrupt(f"signal {signum}")

    # SIGINT explicitly too: a process started in the background inherits SIGINT ignored
    previous = {sig: signal.signal(sig, _terminate) for sig in (signal.SIGTERM, signal.SIGINT)}
    total = config.sessions * session_config.n_steps * session_config.frames_per_step
    try:
        with tqdm(total=total, unit="frame", desc="record") as bar:
            for i, (path, seed) in enumerate(zip(paths, seeds, strict=True)):
                metadata = {
                    "seed": config.seed, "session_index": i,
                    "session_seed": {"entropy": seed.entropy, "spawn_key": list(seed.spawn_key)},
                    "config": session_config.to_dict(), "software": f"onionsort {__version__}",
                    "versions": {"python": platform.python_version(), "numpy": np.__version__,
                                 "pybullet_api": pybullet.getAPIVersion()},
                    "policy": "Boltzmann expert of irl.domains.onion_sorting (true theta)",
                }
                with SortingSession(session_config, policy, initial, seed) as session, \
                        SessionWriter(path, metadata, intrinsics(session_config.camera),
                                      intrinsics(session_config.inspection),
                                      frames_per_step=session_config.frames_per_step,
                                      overwrite=config.overwrite) as writer:
                    for frame in session.frames():
                        writer.write_frame(frame)
                        bar.update()
                logger.info("%s: %d frames, %d steps, %d occluded", path, writer.n_frames,
                            writer.n_steps, int(session.occluded.sum()))
                if rerun_logger is not None:
                    rerun_logger.log_session(open_session(path), i)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        if rerun_logger is not None:
            rerun_logger.close()
