"""``onionsort export``: a session becomes a file other tools read.

``--format ros2`` writes a rosbag2 folder (``metadata.yaml`` and one MCAP file, or SQLite 3 with
``--storage sqlite3``) of CDR-serialised ROS 2 Humble messages: the camera's JPEG and the
inspection view's PNG as ``sensor_msgs/CompressedImage`` (decoded ``rgb8`` images with
``--raw-images``), depth as a ``16UC1`` ``sensor_msgs/Image``, ``CameraInfo`` for each camera,
``/tf``, ``/joint_states``, and the step clock, session record, perception, evaluation and
ground truth as ``std_msgs/String`` JSON (docs/session-format.md has the table). ``ros2 bag
info`` lists it and ``ros2 bag play`` replays it.

Examples
--------
    onionsort export runs/rec/session_000.mcap --format ros2 --out runs/rec/session_000_ros2
    onionsort export runs/rec/session_000.mcap --format ros2 --raw-images --storage sqlite3 \\
        --out runs/rec/session_000_db3
"""

from __future__ import annotations

from pathlib import Path

from onionsort.commands._args import EXPORT_FORMATS, ROS2_STORAGES, subcommand


def register(subparsers) -> None:
    parser = subcommand(subparsers, "export", __doc__,
                        "export a session as a ROS 2 bag (rosbag2 folder)")
    parser.add_argument("session", type=Path, metavar="SESSION", help="a session file (.mcap)")
    parser.add_argument("--format", choices=EXPORT_FORMATS, default="ros2",
                        help="what to write: ros2, a rosbag2 folder (the default, and the only "
                             "format for now)")
    parser.add_argument("--out", type=Path, required=True,
                        help="the folder to create (refused if it exists)")
    parser.add_argument("--raw-images", action="store_true",
                        help="decoded rgb8 sensor_msgs/Image instead of the session's JPEG and "
                             "PNG bytes as CompressedImage")
    parser.add_argument("--storage", choices=ROS2_STORAGES, default="mcap",
                        help="the rosbag2 storage plugin: mcap (default) or sqlite3")
    parser.set_defaults(func=run)


def run(args) -> int:
    from onionsort.stages import ExportConfig, export_session

    s = export_session(ExportConfig(session=args.session, out=args.out, format=args.format,
                                    raw_images=args.raw_images, storage=args.storage))
    print(f"exported {s.n_frames} frames of {args.session} to {s.path} ({s.storage}, "
          f"{s.n_messages} messages on {len(s.topics)} topics)")
    return 0
