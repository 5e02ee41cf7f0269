"""``onionsort import``: a video file or a camera becomes a sensor-only session.

The session holds colour, calibration, a step clock, and the inspection view with
``--inspection`` (no depth, no ground truth); perceive it and learn from it like any other, with
a calibration of its sensor mode (``calibration-video.json``, or
``calibration-video-no-inspection.json`` without ``--inspection``). Steps come from a fixed clock
(``--step-seconds``) or, by default, from changes of the perceived state (debounced).

Examples
--------
    onionsort import line.mp4 --step-seconds 2 --out runs/line/session_000.mcap
    onionsort import line.mp4 --inspection face.mp4 --step-seconds 2 --out runs/line/s0.mcap
    onionsort import --camera 0 --max-seconds 120 --step-seconds 2 --out runs/cam/s0.mcap
"""

from __future__ import annotations

from pathlib import Path

from onionsort.commands._args import add_models_argument, subcommand


def register(subparsers) -> None:
    parser = subcommand(subparsers, "import", __doc__,
                        "import a video file or a camera as a sensor-only session")
    parser.add_argument("video", type=Path, nargs="?", metavar="VIDEO", help="a video file")
    parser.add_argument("--camera", type=int, metavar="INDEX", help="record from a camera")
    parser.add_argument("--out", type=Path, required=True, help="the session file to write")
    parser.add_argument("--step-seconds", type=float, metavar="X",
                        help="a step every X seconds (default: segment by perceived changes)")
    parser.add_argument("--debounce", type=int, default=2,
                        help="windows a perceived change must hold to start a step (2)")
    parser.add_argument("--frames-per-step", type=int, default=3, help="frames kept per step (3)")
    parser.add_argument("--intrinsics", type=Path, metavar="FILE",
                        help="camera intrinsics JSON (default: a 60-degree horizontal view)")
    parser.add_argument("--inspection", type=Path, metavar="VIDEO",
                        help="a video of the inspection spot, frame for frame with VIDEO")
    parser.add_argument("--max-seconds", type=float, default=60.0,
                        help="how long to record from --camera (60)")
    add_models_argument(parser)
    parser.set_defaults(func=run)


def run(args) -> int:
    from onionsort.stages import ImportConfig, import_video

    s = import_video(ImportConfig(
        out=args.out, video=args.video, camera=args.camera, step_seconds=args.step_seconds,
        debounce=args.debounce, frames_per_step=args.frames_per_step,
        intrinsics=args.intrinsics, models=args.models, max_seconds=args.max_seconds,
        inspection=args.inspection))
    print(f"imported {s.source}: {s.frames_read} frames read, {s.steps_written} step(s) of "
          f"{s.frames_per_step} frames written to {s.path}")
    return 0
