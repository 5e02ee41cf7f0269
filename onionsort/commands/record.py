"""``onionsort record``: simulate sorting sessions and record them to MCAP.

A simulated person sorts onions on a conveyor while a passer-by sometimes blocks the camera;
each session becomes ``OUT/session_NNN.mcap`` (see ``recordings.schema`` for the topics).

Examples
--------
    onionsort record --sessions 12 --out runs/rec
    onionsort record --sessions 2 --steps-per-session 10 --occlusion 0.4 --seed 7 \\
        --out runs/rec-small --rerun runs/rec-small/sessions.rrd
"""

from __future__ import annotations

from pathlib import Path

from onionsort.commands._args import add_session_arguments, subcommand


def register(subparsers) -> None:
    parser = subcommand(subparsers, "record", __doc__,
                        "simulate sorting sessions and record them to MCAP")
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
    viewer.add_argument("--connect", metavar="URL",
                        help="also log to a Rerun viewer at URL (rerun+http://HOST:9876/proxy)")
    from robot.difficulty import DIFFICULTY_LEVELS

    parser.add_argument("--difficulty", choices=list(DIFFICULTY_LEVELS), default="clean",
                        help="perception difficulty of the world (clean)")
    parser.set_defaults(func=run)


def run(args) -> int:
    from onionsort.stages import RecordConfig, record

    rerun = args.rerun or args.connect or ("spawn" if args.spawn else None)
    paths = record(RecordConfig(
        out=args.out, sessions=args.sessions, seed=args.seed, occlusion=args.occlusion,
        steps_per_session=args.steps_per_session, frames_per_step=args.frames_per_step,
        width=args.width, height=args.height, overwrite=args.overwrite, rerun=rerun,
        difficulty=args.difficulty))
    print(f"recorded {len(paths)} sessions to {args.out}")
    return 0
