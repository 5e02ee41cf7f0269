"""``onionsort perceive``: add perception topics (detections, state estimates) to sessions.

Reads only each session's sensor side, so it works on sessions without ground truth (imported
from a camera or a video). A session in which perception finds no usable step is an error.

Examples
--------
    onionsort record --sessions 12 --out runs/rec
    onionsort perceive runs/rec/*.mcap
    onionsort perceive runs/rec/*.mcap --executor ray --ray-address auto   # on a Ray cluster
"""

from __future__ import annotations

from pathlib import Path

from onionsort.commands._args import (
    add_device_argument,
    add_models_argument,
    add_parallel_arguments,
    parallel_options,
    subcommand,
)


def register(subparsers) -> None:
    parser = subcommand(subparsers, "perceive", __doc__,
                        "add perception topics (detections, state estimates) to sessions")
    parser.add_argument("sessions", type=Path, nargs="+", metavar="SESSION.mcap")
    parser.add_argument("--replace", action="store_true",
                        help="perceive sessions that already hold perception topics again")
    add_models_argument(parser)
    add_device_argument(parser)
    add_parallel_arguments(parser, pieces="sessions")
    parser.set_defaults(func=run)


def run(args) -> int:
    from onionsort.stages import PerceiveConfig, perceive

    done = perceive(PerceiveConfig(sessions=tuple(args.sessions), models=args.models,
                                   replace=args.replace, device=args.device,
                                   **parallel_options(args)))
    for s in done:
        mode = "RGB-D" if s.depth else "colour only"
        print(f"{s.path}: {s.n_steps} steps, {s.n_occluded} called occluded ({mode})")
    print(f"perceived {len(done)} session(s); perception topics added in place")
    return 0
