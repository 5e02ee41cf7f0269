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

from pathlib import Path

from onionsort.commands._args import add_models_argument, subcommand


def register(subparsers) -> None:
    parser = subcommand(subparsers, "import", __doc__,
                        "import a video file, a ROS bag or a camera as a sensor-only session")
    parser.add_argument("video", type=Path, nargs="?", metavar="SOURCE",
                        help="a video file, or a ROS 2 / ROS 1 bag")
    parser.add_argument("--camera", type=int, metavar="INDEX", help="record from a camera")
    parser.add_argument("--out", type=Path, help="the session file to write")
    parser.add_argument("--step-seconds", type=float, metavar="X",
                        help="a step every X seconds (default: segment by perceived changes)")
    parser.add_argument("--debounce", type=int, default=2,
                        help="windows a perceived change must hold to start a step (2)")
    parser.add_argument("--frames-per-step", type=int, default=3, help="frames kept per step (3)")
    parser.add_argument("--intrinsics", type=Path, metavar="FILE",
                        help="camera intrinsics JSON (default: a bag's CameraInfo, else a "
                             "60-degree horizontal view)")
    parser.add_argument("--inspection", type=Path, metavar="VIDEO",
                        help="a video of the inspection spot, frame for frame with VIDEO")
    parser.add_argument("--max-seconds", type=float, default=60.0,
                        help="how long to record from --camera (60)")
    bag = parser.add_argument_group("a bag")
    bag.add_argument("--list", action="store_true",
                     help="print the bag's topics and which ones the import can use, and stop")
    bag.add_argument("--color-topic", metavar="TOPIC",
                     help="the colour images (default: the bag's one colour image topic)")
    bag.add_argument("--depth-topic", metavar="TOPIC",
                     help="depth images, 16UC1 millimetres or 32FC1 metres (optional)")
    bag.add_argument("--camera-info-topic", metavar="TOPIC",
                     help="the colour camera's CameraInfo (default: the one beside "
                          "--color-topic, then --intrinsics)")
    bag.add_argument("--inspection-topic", metavar="TOPIC",
                     help="images of the inspection spot (optional)")
    bag.add_argument("--step-topic", metavar="TOPIC",
                     help="a topic whose messages mark step starts")
    bag.add_argument("--sync-tolerance", type=float, default=0.05, metavar="SECONDS",
                     help="how near in time depth and inspection images must be to a colour "
                          "frame (0.05)")
    add_models_argument(parser)
    parser.set_defaults(func=run)


def run(args) -> int:
    from onionsort.stages import ImportConfig, import_video, list_bag

    if args.list:
        return _print_topics(list_bag(args.video))
    if args.out is None:
        raise ValueError("--out is required: the session file to write")
    s = import_video(ImportConfig(
        out=args.out, video=args.video, camera=args.camera, step_seconds=args.step_seconds,
        debounce=args.debounce, frames_per_step=args.frames_per_step,
        intrinsics=args.intrinsics, models=args.models, max_seconds=args.max_seconds,
        inspection=args.inspection, color_topic=args.color_topic, depth_topic=args.depth_topic,
        camera_info_topic=args.camera_info_topic, inspection_topic=args.inspection_topic,
        step_topic=args.step_topic, sync_tolerance=args.sync_tolerance))
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
