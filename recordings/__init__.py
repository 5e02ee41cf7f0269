"""Sessions on disk and the frames that make them.

- the session format, sensor side and optional ground truth (:mod:`recordings.schema`), its
  MCAP writer and reader (:mod:`recordings.writer`, :mod:`recordings.reader`), atomic rewrites
  (:mod:`recordings.rewrite`: perception topics, stripping ground truth), step grouping
  (:mod:`recordings.steps`);
- frame sources for a video file or a camera and the import of their frames as a session
  (:mod:`recordings.sources`, :mod:`recordings.segmentation`, :mod:`recordings.video_import`);
- robots' bags: ROS 2 and ROS 1 bags (and Foxglove protobuf MCAP files) imported as sessions
  (:mod:`recordings.bags`), sessions exported as rosbag2 folders (:mod:`recordings.ros_export`);
- labelled datasets for perception (:mod:`recordings.dataset`), and the formats annotation
  tools read and write: COCO (:mod:`recordings.coco`), YOLO (:mod:`recordings.yolo`), state
  labels as CSV (:mod:`recordings.states_csv`);
- all Rerun logging (:mod:`recordings.rerun`, imported on demand: it loads the Rerun SDK).
"""

from recordings.reader import (
    NotASessionError,
    RecordingDamagedError,
    Session,
    open_session,
    read_demonstrations,
)
from recordings.rewrite import strip_ground_truth
from recordings.sources import write_video
from recordings.writer import SessionWriter

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
