"""Sessions on disk, the frames that make them, the labelled data made of them.

- :mod:`recordings.session`: the session format, sensor side and optional ground truth
  (schema, perception topics), its MCAP writer and reader, atomic rewrites, step grouping, the
  3D side;
- :mod:`recordings.sources`: frame sources for a video file or a camera, robots' ROS bags, and
  their import as sessions; sessions exported as rosbag2 folders;
- :mod:`recordings.labels`: labelled datasets for perception, and the formats annotation tools
  read and write (COCO, YOLO, Label Studio, state and line-up CSVs);
- :mod:`recordings.rerun`: the common Rerun logging (imported on demand: it loads the Rerun
  SDK).
"""

from recordings.session.reader import (
    NotASessionError,
    RecordingDamagedError,
    Session,
    open_session,
    read_demonstrations,
)
from recordings.session.rewrite import strip_ground_truth
from recordings.session.writer import SessionWriter
from recordings.sources.video import write_video

__all__ = [
    "NotASessionError",
    "RecordingDamagedError",
    "Session",
    "SessionWriter",
    "open_session",
    "read_demonstrations",
    "strip_ground_truth",
    "write_video",
]
