"""``onionsort import``: a video file, a robot's bag or a camera becomes a sensor-only session.

The session holds colour, calibration, a step clock, and the inspection view with
``--inspection`` or ``--inspection-topic`` (no ground truth; depth only from a bag's
``--depth-topic``); perceive it and learn from it like any other, with a calibration of its
sensor mode. Steps come from a fixed clock (``--step-seconds``), from a bag's topic that marks
step starts (``--step-topic``) or, by default, from changes of the perceived state (debounced).

A bag is a rosbag2 folder (MCAP or sqlite3), one of its files, a ROS 1 ``.bag``, or an MCAP
file of Foxglove protobuf images another tool wrote:
``--list`` prints its topics and which of them the import can use; with one usable colour topic
``--color-topic`` may be left out.

Examples
--------
    onionsort import line.mp4 --step-seconds 2 --out runs/line/session_000.mcap
    onionsort import line.mp4 --inspection face.mp4 --step-seconds 2 --out runs/line/s0.mcap
    onionsort import --camera 0 --max-seconds 120 --step-seconds 2 --out runs/cam/s0.mcap
    onionsort import cell_bag --list
    onionsort import cell_bag --color-topic /camera/color --depth-topic /camera/depth \\
        --inspection-topic /inspection/color --step-seconds 2 --out runs/cell/s0.mcap
"""

from __future__ import annotations

from dataclasses import dataclass

from onionsort.commands import add_command
from onionsort.configs import config_from_args, option
from onionsort.configs.import_video import ImportConfig


@dataclass(frozen=True)
class ImportCommand(ImportConfig):
    """The command's options: the stage's, and ``--list``."""

    list: bool = option(False, exclusive="target", after="out",
                        help="print the bag's topics and which ones the import can use, and "
                             "stop (instead of --out)")


def register(subparsers) -> None:
    add_command(subparsers, "import", __doc__,
                "import a video file, a ROS bag or a camera as a sensor-only session",
                ImportCommand, run)


def run(args) -> int:
    from onionsort.stages import import_video, list_bag

    if args.list:
        return _print_topics(list_bag(args.video))
    s = import_video(config_from_args(ImportConfig, args))
    print(f"imported {s.source}: {s.frames_read} frames read, {s.steps_written} step(s) of "
          f"{s.frames_per_step} frames written to {s.path}")
    return 0


def _print_topics(topics) -> int:
    rows = [("topic", "type", "messages", "rate (Hz)", "import can use it as")]
    rows += [(t.name, t.msgtype, str(t.count), f"{t.rate_hz:.1f}" if t.rate_hz else "-",
              t.use or "steps (--step-topic)") for t in topics]
    widths = [max(len(r[i]) for r in rows) for i in range(4)]
    for r in rows:
        print("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=False)) + "  " + r[4])
    colour = [t.name for t in topics if t.usable_image == "colour"]
    print(f"{len(colour)} colour topic(s) the import can read"
          + (f": {', '.join(colour)}" if colour else ""))
    return 0
