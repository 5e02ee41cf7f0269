"""``onionsort record``: simulate sorting sessions and record them to MCAP.

A simulated person sorts onions on a conveyor while a passer-by sometimes blocks the camera;
each session becomes ``OUT/session_NNN.mcap`` (see ``recordings.session.schema`` for the topics).
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

from dataclasses import dataclass

from onionsort.commands import add_command
from onionsort.configs import config_from_args, option
from onionsort.configs.record import RecordConfig


@dataclass(frozen=True, kw_only=True)
class RecordCommand(RecordConfig):
    """The command's options: the stage's, and ``--spawn`` (a viewer instead of a file)."""

    spawn: bool = option(False, exclusive="viewer", after="rerun",
                         help="also log to a local Rerun viewer")


def register(subparsers) -> None:
    add_command(subparsers, "record", __doc__,
                "simulate sorting sessions and record them to MCAP", RecordCommand, run)


def run(args) -> int:
    from onionsort.stages import record

    rerun = args.rerun or ("spawn" if args.spawn else None)
    paths = record(config_from_args(RecordConfig, args, rerun=rerun))
    print(f"recorded {len(paths)} sessions to {args.out}" + (" (complete ones kept)"
                                                             if args.resume else ""))
    return 0
