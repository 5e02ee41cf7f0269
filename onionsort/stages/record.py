"""Stage ``record``: simulate sorting sessions and write one MCAP file per session.

A simulated person sorts onions on a conveyor, acting on the expert's Boltzmann policy, while a
passer-by sometimes walks through the camera's view. Each session is written to
``OUT/session_NNN.mcap`` frame by frame: its sensor side (colour, depth, calibration, the step
clock, the inspection view) and its ground truth (see :mod:`recordings.session.schema`). Ctrl-C or
SIGTERM finishes the open file with status ``interrupted``.

``resume`` continues an interrupted recording in ``out``: a session is kept when it is complete
(it opens with the reader's CRC-validating read, its end record says ``complete`` and it holds
all its steps) and was recorded with the same settings; an interrupted or damaged one (and a
``session_NNN.mcap.partial`` left by a process killed while opening it) is deleted and recorded
again from the same per-session seed, so the result is the one an uninterrupted run gives.

Example::

    from onionsort.stages import RecordConfig, record
    paths = record(RecordConfig(out=Path("runs/rec"), sessions=2, steps_per_session=10))
"""

from __future__ import annotations

import logging
from pathlib import Path

from onionsort.configs.record import RecordConfig
from onionsort.stages.base import log_config, output_folder
from onionsort.stages.parallel import run_pieces

__all__ = ["RecordConfig", "record"]

logger = logging.getLogger(__name__)


def record(config: RecordConfig) -> list[Path]:
    """Record ``config.sessions`` sessions (with ``config.resume``, those not complete yet);
    return the paths of all of them."""
    log_config("record", config)
    if config.connect is not None:
        from recordings.rerun.common import reach_viewer

        reach_viewer(config.connect)  # a wrong address fails now, not after the recording
    with output_folder(config.out) as out:  # checked before anything is imported or rendered
        paths = [out / f"session_{i:03d}.mcap" for i in range(config.sessions)]
        if config.resume:
            todo = _sessions_to_record(config, paths)
        else:
            existing = [p for p in paths if p.exists()]
            if existing and not config.overwrite:
                raise FileExistsError(
                    f"{existing[0]} exists ({len(existing)} session files in {out}); pass "
                    "--resume to keep the complete ones and record the rest, --overwrite to "
                    "replace them, or choose another --out")
            todo = list(range(config.sessions))
        _record_sessions(config, paths, todo)
    return paths


def _session_config(config: RecordConfig):
    """The simulator's :class:`robot.simulation.SessionConfig` of every session."""
    import dataclasses

    from robot.camera import CameraSpec
    from robot.simulation import SessionConfig

    return SessionConfig(
        n_steps=config.steps_per_session, occlusion=config.occlusion,
        frames_per_step=config.frames_per_step,
        camera=dataclasses.replace(CameraSpec(), width=config.width, height=config.height),
        difficulty=config.difficulty,
    )


def _settings(config: RecordConfig, index: int, seed) -> dict:
    """What a session's metadata must say for it to belong to this recording (JSON values)."""
    import json

    return json.loads(json.dumps({
        "seed": config.seed, "session_index": index,
        "session_seed": {"entropy": seed.entropy, "spawn_key": list(seed.spawn_key)},
        "config": _session_config(config).to_dict()}))


def _sessions_to_record(config: RecordConfig, paths: list[Path]) -> list[int]:
    """The indices of the sessions a resumed recording still has to record; the interrupted
    or damaged ones among them (and temporary files) are deleted here.

    Raises
    ------
    ValueError
        If a file in the way is no session, or a session was recorded with other settings.
    """
    import numpy as np

    from recordings.session.reader import NotASessionError, RecordingDamagedError, open_session

    seeds = np.random.SeedSequence(config.seed).spawn(config.sessions)
    todo = []
    for i, (path, seed) in enumerate(zip(paths, seeds, strict=True)):
        path.with_name(path.name + ".partial").unlink(missing_ok=True)
        if not path.exists():
            todo.append(i)
            continue
        try:
            session = open_session(path)
        except RecordingDamagedError:
            session = None  # killed while recording: the file ends in the middle of a frame
        except NotASessionError as exc:
            raise ValueError(f"cannot resume: {exc}; remove it or choose another "
                             "--out") from None
        if session is not None:
            want = _settings(config, i, seed)
            differ = [k for k in want if k != "config" and session.metadata.get(k) != want[k]]
            have = session.metadata.get("config") or {}
            differ += [f"config.{k}" for k in want["config"] if have.get(k) != want["config"][k]]
            if differ:
                raise ValueError(f"cannot resume: {path} was recorded with other settings "
                                 f"({', '.join(differ)} differ); resume with the settings it "
                                 "was recorded with, or choose another --out")
            if session.status == "complete" and \
                    len(session.step_frames()) == config.steps_per_session:
                logger.info("%s: complete, kept", path)
                continue
        logger.info("%s: %s, recorded again", path,
                    "damaged" if session is None else session.status)
        path.unlink()
        todo.append(i)
    return todo


def _record_sessions(config: RecordConfig, paths: list[Path], todo: list[int]) -> None:
    """Record the sessions ``todo`` (indices into ``paths``), each a piece of the executor;
    log every session to Rerun."""
    import signal

    import numpy as np

    from recordings import open_session

    seeds = np.random.SeedSequence(config.seed).spawn(config.sessions)
    rerun_logger = None
    if config.rerun is not None or config.connect is not None:
        from recordings.rerun import SessionLogger
        from recordings.rerun.common import rerun_targets

        rerun_logger = SessionLogger(rerun_targets(config.rerun, config.connect))

    def _terminate(signum, _frame):  # finish the open file on SIGTERM as on Ctrl-C
        raise KeyboardInterrupt(f"signal {signum}")

    # SIGINT explicitly too: a process started in the background inherits SIGINT ignored
    previous = {sig: signal.signal(sig, _terminate) for sig in (signal.SIGTERM, signal.SIGINT)}
    pieces = [(paths[i], seeds[i], i, config) for i in todo]
    try:
        for _ in run_pieces(_record_piece, pieces, config, names=[paths[i].name for i in todo],
                            desc="record", unit="session"):
            pass
        if rerun_logger is not None:
            for i, path in enumerate(paths):
                rerun_logger.log_session(open_session(path), i)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        if rerun_logger is not None:
            rerun_logger.close()


def _record_piece(piece: tuple) -> Path:
    """Record one session: ``piece`` is ``(path, seed, index, config)``."""
    from robot.simulation import expert_model

    path, seed, index, config = piece
    session_config = _session_config(config)
    _record_session(path, seed, index, config, session_config,
                    expert_model(session_config.blemish_rate))
    return path


def _record_session(path: Path, seed, index: int, config: RecordConfig, session_config,
                    expert: tuple) -> None:
    """Simulate session ``index`` from its seed and write it to ``path``; ``expert`` is the
    sorter's ``(policy, initial)``."""
    import platform

    import numpy as np
    import pybullet

    from onionsort import __version__
    from recordings import SessionWriter
    from robot.camera import intrinsics
    from robot.simulation import SortingSession

    metadata = {
        **_settings(config, index, seed), "software": f"onionsort {__version__}",
        "versions": {"python": platform.python_version(), "numpy": np.__version__,
                     "pybullet_api": pybullet.getAPIVersion()},
        "policy": "Boltzmann expert of irl.domains.onion_sorting (true theta)",
    }
    with SortingSession(session_config, *expert, seed) as session, \
            SessionWriter(path, metadata, intrinsics(session_config.camera),
                          intrinsics(session_config.inspection),
                          frames_per_step=session_config.frames_per_step,
                          overwrite=config.overwrite) as writer:
        for frame in session.frames():
            writer.write_frame(frame)
    logger.info("%s: %d frames, %d steps, %d occluded", path, writer.n_frames,
                writer.n_steps, int(session.occluded.sum()))
