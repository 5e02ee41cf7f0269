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

from onionsort.commands import add_command
from onionsort.configs import config_from_args
from onionsort.configs.export import ExportConfig


def register(subparsers) -> None:
    add_command(subparsers, "export", __doc__,
                "export a session as a ROS 2 bag (rosbag2 folder)", ExportConfig, run)


def run(args) -> int:
    from onionsort.stages import export_session

    s = export_session(config_from_args(ExportConfig, args))
    print(f"exported {s.n_frames} frames of {args.session} to {s.path} ({s.storage}, "
          f"{s.n_messages} messages on {len(s.topics)} topics)")
    return 0
