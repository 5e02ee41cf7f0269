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

from onionsort.commands import add_command
from onionsort.configs import config_from_args
from onionsort.configs.perceive import PerceiveConfig


def register(subparsers) -> None:
    add_command(subparsers, "perceive", __doc__,
                "add perception topics (detections, state estimates) to sessions",
                PerceiveConfig, run)


def run(args) -> int:
    from onionsort.stages import perceive

    done = perceive(config_from_args(PerceiveConfig, args))
    for s in done:
        mode = "RGB-D" if s.depth else "colour only"
        print(f"{s.path}: {s.n_steps} steps, {s.n_occluded} called occluded ({mode})")
    print(f"perceived {len(done)} session(s); perception topics added in place")
    return 0
