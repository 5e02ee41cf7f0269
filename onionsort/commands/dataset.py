"""``onionsort dataset``: render labelled frames (train/val/test) for perception.

Frames come from whole simulated sessions, split into train, val and test by session. See
``recordings.dataset`` for the folder layout and the label records.

Examples
--------
    onionsort dataset --frames 3000 --seed 0 --out runs/data
    onionsort dataset --frames 300 --occlusion 0.4 --seed 1 --out runs/data-small
    onionsort dataset --frames 8000 --difficulty clean,realistic,paper,hard --out runs/data-mix
    onionsort dataset --frames 8000 --randomize-look --out runs/data-looks

``--randomize-look`` gives each session and robot line-up a look of its own, drawn from its
seed (``robot.look``: the light's colour, intensity and direction; the colours of the floor,
belt, stand and bin; the cameras' exposure and white balance), for models that must survive
another camera. The difficulty levels are unchanged by it.
"""

from __future__ import annotations

from pathlib import Path

from onionsort.commands._args import (
    add_parallel_arguments,
    add_session_arguments,
    parallel_options,
    subcommand,
)


def register(subparsers) -> None:
    parser = subcommand(subparsers, "dataset", __doc__,
                        "render labelled frames (train/val/test) for perception")
    parser.add_argument("--frames", type=int, default=3000, help="frames in all (3000)")
    parser.add_argument("--out", type=Path, required=True, help="new dataset folder")
    add_session_arguments(parser, occlusion=0.3)
    parser.add_argument("--val", type=float, default=0.15, help="share of sessions for val")
    parser.add_argument("--test", type=float, default=0.15, help="share of sessions for test")
    parser.add_argument("--robot-onions", type=int, default=120,
                        help="onions the Sawyer holds up to its inspection camera, in line-ups "
                             "of 10 split like the sessions (120; 0 for none)")
    parser.add_argument("--robot-views", type=int, default=8,
                        help="views the Sawyer takes of each of them (8)")
    from robot.difficulty import DIFFICULTY_LEVELS

    parser.add_argument("--difficulty", type=_levels, default="clean",
                        help="perception difficulty of the world: one of "
                             f"{', '.join(DIFFICULTY_LEVELS)} (clean), or several joined by "
                             "commas for a mix whose sessions take the levels in turn")
    parser.add_argument("--randomize-look", action="store_true",
                        help="draw each session's and line-up's light, surface colours and "
                             "camera exposure and white balance from its seed (training data "
                             "across cameras; default: today's look)")
    add_parallel_arguments(parser, pieces="sessions and line-ups")
    parser.set_defaults(func=run)


def _levels(text: str) -> str:
    """One difficulty level or several joined by commas, for argparse ``type=``."""
    import argparse

    from robot.difficulty import DIFFICULTY_LEVELS

    unknown = [x for x in text.split(",") if x.strip() not in DIFFICULTY_LEVELS]
    if unknown:
        raise argparse.ArgumentTypeError(
            f"unknown level {unknown[0].strip()!r}; the levels are {', '.join(DIFFICULTY_LEVELS)}")
    return ",".join(x.strip() for x in text.split(","))


def run(args) -> int:
    from onionsort.stages import DatasetConfig, make_dataset

    summary = make_dataset(DatasetConfig(
        out=args.out, frames=args.frames, seed=args.seed, occlusion=args.occlusion,
        steps_per_session=args.steps_per_session, frames_per_step=args.frames_per_step,
        val=args.val, test=args.test, robot_onions=args.robot_onions, difficulty=args.difficulty,
        robot_views=args.robot_views, randomize_look=args.randomize_look,
        **parallel_options(args)))
    sessions = ", ".join(f"{s}: {n} sessions" for s, n in summary.sessions.items())
    print(f"wrote {summary.frames} frames ({sessions}) to {args.out}")
    if summary.robot_views:
        print(f"wrote {summary.robot_views} inspection views of the Sawyer holding "
              f"{args.robot_onions} onions")
    return 0
