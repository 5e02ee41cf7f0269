"""``onionsort record``: simulate sorting sessions and write one MCAP file per session.

A simulated person sorts onions on a conveyor, acting on the expert's Boltzmann policy, while a
passer-by sometimes walks through the camera's view. Each session is written to
``OUT/session_NNN.mcap`` frame by frame (see :mod:`recordings.schema` for the topics).

Examples
--------
    onionsort record --sessions 12 --out runs/rec
    onionsort record --sessions 2 --steps-per-session 10 --occlusion 0.4 --seed 7 \\
        --out runs/rec-small --rerun runs/rec-small/sessions.rrd
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from onionsort.commands._session_args import add_session_arguments

__all__ = ["register"]

logger = logging.getLogger(__name__)


def register(subparsers) -> None:
    """Add the ``record`` subcommand."""
    parser = subparsers.add_parser(
        "record", help="simulate sorting sessions and record them to MCAP",
        description="Simulate onion-sorting sessions watched by a sometimes-occluded camera and "
        "write one MCAP file per session (see recordings.schema for the topics).",
    )
    parser.add_argument("--sessions", type=int, default=12, help="sessions to record (12)")
    parser.add_argument("--out", type=Path, required=True, help="folder for the .mcap files")
    add_session_arguments(parser, occlusion=0.2)
    parser.add_argument("--width", type=int, default=320, help="camera width in pixels (320)")
    parser.add_argument("--height", type=int, default=240, help="camera height in pixels (240)")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace existing session files in --out")
    viewer = parser.add_mutually_exclusive_group()
    viewer.add_argument("--rerun", type=Path, metavar="FILE.rrd",
                        help="also log every session to this Rerun file")
    viewer.add_argument("--spawn", action="store_true", help="also log to a Rerun viewer")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Record ``args.sessions`` sessions; returns the exit code."""
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

    if args.sessions < 1:
        raise ValueError(f"--sessions must be >= 1; got {args.sessions}")
    config = SessionConfig(
        n_steps=args.steps_per_session, occlusion=args.occlusion,
        frames_per_step=args.frames_per_step,
        camera=dataclasses.replace(CameraSpec(), width=args.width, height=args.height),
    )
    out: Path = args.out
    paths = [out / f"session_{i:03d}.mcap" for i in range(args.sessions)]
    existing = [p for p in paths if p.exists()]
    if existing and not args.overwrite:
        raise FileExistsError(f"{existing[0]} exists ({len(existing)} session files in {out}); "
                              "pass --overwrite or choose another --out")
    logger.info("recording %d sessions to %s with %s (seed %d)", args.sessions, out, config,
                args.seed)
    policy, initial = expert_model(config.blemish_rate)
    seeds = np.random.SeedSequence(args.seed).spawn(args.sessions)
    rerun_logger = None
    if args.rerun or args.spawn:
        from recordings.rerun_log import RerunSessionLogger

        rerun_logger = RerunSessionLogger("spawn" if args.spawn else args.rerun)

    def _terminate(signum, _frame):  # finish the open file on SIGTERM as on Ctrl-C
        raise KeyboardInterrupt(f"signal {signum}")

    # SIGINT explicitly too: a process started in the background inherits SIGINT ignored
    previous = {sig: signal.signal(sig, _terminate) for sig in (signal.SIGTERM, signal.SIGINT)}
    total = args.sessions * config.n_steps * config.frames_per_step
    try:
        with tqdm(total=total, unit="frame", desc="record") as bar:
            for i, (path, seed) in enumerate(zip(paths, seeds, strict=True)):
                metadata = {
                    "seed": args.seed, "session_index": i,
                    "session_seed": {"entropy": seed.entropy, "spawn_key": list(seed.spawn_key)},
                    "config": config.to_dict(), "software": f"onionsort {__version__}",
                    "versions": {"python": platform.python_version(), "numpy": np.__version__,
                                 "pybullet_api": pybullet.getAPIVersion()},
                    "policy": "Boltzmann expert of irl.domains.onion_sorting (true theta)",
                }
                with SortingSession(config, policy, initial, seed) as session, SessionWriter(
                    path, metadata, intrinsics(config.camera), intrinsics(config.inspection),
                    overwrite=args.overwrite,
                ) as writer:
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
    return 0
