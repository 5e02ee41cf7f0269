"""``onionsort record``: simulate sorting sessions and record them to MCAP.

A simulated person sorts onions on a conveyor while a passer-by sometimes blocks the camera;
each session becomes ``OUT/session_NNN.mcap`` (see ``recordings.schema`` for the topics).
``--resume`` continues an interrupted recording: complete sessions are kept, interrupted ones
recorded again from their own seeds. ``--connect URL`` streams the Rerun recording to a viewer
on another machine, in addition to the ``--rerun`` file.

Examples
--------
    onionsort record --sessions 12 --out runs/rec
    onionsort record --sessions 2 --steps-per-session 10 --occlusion 0.4 --seed 7 \\
        --out runs/rec-small --rerun runs/rec-small/sessions.rrd
    onionsort record --sessions 12 --out runs/rec --resume
    onionsort record --sessions 12 --out runs/rec --rerun runs/rec/sessions.rrd \\
        --connect rerun+http://192.168.1.20:9876/proxy
"""

from __future__ import annotations

from pathlib import Path

from onionsort.commands._args import (
    add_connect_argument,
    add_parallel_arguments,
    add_session_arguments,
    parallel_options,
    subcommand,
)


def register(subparsers) -> None:
    parser = subcommand(subparsers, "record", __doc__,
                        "simulate sorting sessions and record them to MCAP")
    parser.add_argument("--sessions", type=int, default=12, help="sessions to record (12)")
    parser.add_argument("--out", type=Path, required=True, help="folder for the .mcap files")
    add_session_arguments(parser, occlusion=0.2)
    parser.add_argument("--width", type=int, default=320, help="camera width in pixels (320)")
    parser.add_argument("--height", type=int, default=240, help="camera height in pixels (240)")
    again = parser.add_mutually_exclusive_group()
    again.add_argument("--overwrite", action="store_true",
                       help="replace existing session files in --out")
    again.add_argument("--resume", action="store_true",
                       help="keep the complete sessions in --out and record the others "
                            "(interrupted ones again, from their own seeds)")
    viewer = parser.add_mutually_exclusive_group()
    viewer.add_argument("--rerun", type=Path, metavar="FILE.rrd",
                        help="also log every session to this Rerun file")
    viewer.add_argument("--spawn", action="store_true", help="also log to a local Rerun viewer")
    add_connect_argument(parser, what="every session")
    from robot.difficulty import DIFFICULTY_LEVELS

    parser.add_argument("--difficulty", choices=list(DIFFICULTY_LEVELS), default="clean",
                        help="perception difficulty of the world (clean)")
    add_parallel_arguments(parser, pieces="sessions")
    parser.set_defaults(func=run)


def run(args) -> int:
    from onionsort.stages import RecordConfig, record

    rerun = args.rerun or ("spawn" if args.spawn else None)
    paths = record(RecordConfig(
        out=args.out, sessions=args.sessions, seed=args.seed, occlusion=args.occlusion,
        steps_per_session=args.steps_per_session, frames_per_step=args.frames_per_step,
        width=args.width, height=args.height, overwrite=args.overwrite, rerun=rerun,
        difficulty=args.difficulty, connect=args.connect, resume=args.resume,
        **parallel_options(args)))
    print(f"recorded {len(paths)} sessions to {args.out}" + (" (complete ones kept)"
                                                             if args.resume else ""))
    return 0
