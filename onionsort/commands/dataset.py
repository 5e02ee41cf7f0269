"""``onionsort dataset``: render labelled frames of the sorting world for perception.

Frames come from whole simulated sessions (the sorter acting on the expert's policy, the
passer-by occluding the camera), split into train, val and test by session. See
:mod:`recordings.dataset` for the folder layout and the label records.

Examples
--------
    onionsort dataset --frames 3000 --seed 0 --out runs/data
    onionsort dataset --frames 300 --occlusion 0.4 --seed 1 --out runs/data-small
"""

from __future__ import annotations

import argparse
import logging
import math
from pathlib import Path

from onionsort.commands._session_args import add_session_arguments

__all__ = ["register", "split_plan"]

logger = logging.getLogger(__name__)


def register(subparsers) -> None:
    """Add the ``dataset`` subcommand."""
    parser = subparsers.add_parser(
        "dataset", help="render labelled frames (train/val/test) for perception",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--frames", type=int, default=3000, help="frames in all (3000)")
    parser.add_argument("--out", type=Path, required=True, help="new dataset folder")
    add_session_arguments(parser, occlusion=0.3)
    parser.add_argument("--val", type=float, default=0.15, help="share of sessions for val")
    parser.add_argument("--test", type=float, default=0.15, help="share of sessions for test")
    parser.add_argument("--robot-onions", type=int, default=120,
                        help="onions the Sawyer holds up to the inspection camera, 3 views each, "
                             "in line-ups of 10 split like the sessions (120; 0 for none)")
    parser.set_defaults(func=run)


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


def run(args: argparse.Namespace) -> int:
    """Render ``args.frames`` labelled frames into ``args.out``; returns the exit code."""
    import numpy as np
    from tqdm import tqdm

    from onionsort import __version__
    from recordings.dataset import DatasetWriter
    from robot.simulation import SessionConfig, SortingSession, expert_model

    if args.frames < 1:
        raise ValueError(f"--frames must be >= 1; got {args.frames}")
    if args.robot_onions < 0:
        raise ValueError(f"--robot-onions must be >= 0; got {args.robot_onions}")
    config = SessionConfig(n_steps=args.steps_per_session, occlusion=args.occlusion,
                           frames_per_step=args.frames_per_step)
    per_session = config.n_steps * config.frames_per_step
    n_sessions = math.ceil(args.frames / per_session)
    plan = split_plan(n_sessions, args.val, args.test)
    writer = DatasetWriter(args.out, {
        "seed": args.seed, "frames": args.frames, "sessions": n_sessions,
        "config": config.to_dict(), "software": f"onionsort {__version__}",
        "session_splits": plan,
    })
    logger.info("rendering %d frames from %d sessions into %s", args.frames, n_sessions, args.out)
    policy, initial = expert_model(config.blemish_rate)
    seeds = np.random.SeedSequence([args.seed, 0x0D47A5E7]).spawn(n_sessions)
    written = 0
    try:
        with tqdm(total=args.frames, unit="frame", desc="dataset") as bar:
            for k, (split, seed) in enumerate(zip(plan, seeds, strict=True)):
                with SortingSession(config, policy, initial, seed) as session:
                    for frame in session.frames():
                        if written == args.frames:
                            break
                        writer.add(split, frame, session=k)
                        written += 1
                        bar.update()
                writer.flush(split)
    finally:
        writer.close()
    sessions = ", ".join(f"{s}: {plan.count(s)} sessions" for s in dict.fromkeys(plan))
    print(f"wrote {written} frames ({sessions}) to {args.out}")
    if args.robot_onions:
        n = _robot_views(writer, args)
        print(f"wrote {n} inspection views of the Sawyer holding {args.robot_onions} onions")
    return 0


def _robot_views(writer, args: argparse.Namespace) -> int:
    """Add the Sawyer's inspection views, line-ups of 10 onions split like the sessions."""
    import numpy as np
    from tqdm import tqdm

    from robot.station import robot_inspection_views

    sizes = [10] * (args.robot_onions // 10) + ([args.robot_onions % 10]
                                               if args.robot_onions % 10 else [])
    plan = (split_plan(len(sizes), args.val, args.test) if len(sizes) >= 3
            else ["train"] * len(sizes))
    seeds = np.random.SeedSequence([args.seed, 0x5A3E7]).spawn(len(sizes))
    n = 0
    try:
        for k, (size, split, seed) in enumerate(tqdm(list(zip(sizes, plan, seeds, strict=True)),
                                                     desc="robot views", unit="line-up")):
            for index, rgb, labels in robot_inspection_views(size, seed):
                writer.add_robot_view(split, rgb, labels, lineup=k, index=index)
                n += 1
            writer.flush(split)
    finally:
        writer.close()
    return n
