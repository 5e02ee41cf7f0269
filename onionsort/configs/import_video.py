"""The config of stage ``import`` (:mod:`onionsort.stages.import_video`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from onionsort.configs import common, documented, option

__all__ = ["ImportConfig"]

#: The title of the options that read a bag
BAG = "a bag"


@documented
@dataclass(frozen=True)
class ImportConfig:
    """Where the frames come from, how they are cut into steps, and where the session goes.

    The source is exactly one of ``video`` and ``camera`` (an index for
    ``cv2.VideoCapture``). ``video`` is a video file (any container and codec OpenCV reads)
    or a ROS 2 or ROS 1 bag (a rosbag2 folder, one of its files, a ``.bag``;
    :mod:`recordings.sources.bags`), told apart by what the path is
    (:func:`recordings.sources.bags.is_bag`). ``intrinsics`` is JSON, ``{"K": 3x3}`` or ``{"fx",
    "fy", "cx", "cy"}``; ``models`` segment the steps by perceived changes; the state
    classifier reads 3 frames a step. An existing ``out`` is refused.
    """

    out: Path = option(exclusive="target", after="camera",
                       help="the session file to write (or --list)")
    video: Path | None = option(None, positional=True, nargs="?", metavar="SOURCE",
                                help="a video file, or a ROS 2 / ROS 1 bag (default: none, "
                                     "with --camera)")
    camera: int | None = option(None, metavar="INDEX",
                                help="record from the camera of this index instead of SOURCE "
                                     "(default: none)")
    step_seconds: float | None = option(None, metavar="X",
                                        help="a step every X seconds (default: segment by "
                                             "perceived changes)")
    debounce: int = option(2, help="windows a perceived change must hold to start a step")
    frames_per_step: int = common.frames_per_step("frames kept per step")
    intrinsics: Path | None = option(None, metavar="FILE",
                                     help="camera intrinsics JSON (default: a bag's CameraInfo, "
                                          "else a 60-degree horizontal view)")
    inspection: Path | None = option(None, metavar="VIDEO",
                                     help="a video of the inspection spot, frame for frame "
                                          "with SOURCE (default: none: no inspection view)")
    max_seconds: float = option(60.0, help="how long to record from --camera, in seconds")
    #: The intrinsics JSON of ``inspection`` (None: a 60-degree horizontal view).
    inspection_intrinsics: Path | None = None
    color_topic: str | None = option(None, metavar="TOPIC", group=BAG,
                                     help="the colour images (default: the bag's one colour "
                                          "image topic)")
    depth_topic: str | None = option(None, metavar="TOPIC", group=BAG,
                                     help="depth images, 16UC1 millimetres or 32FC1 metres "
                                          "(default: none: no depth)")
    camera_info_topic: str | None = option(None, metavar="TOPIC", group=BAG,
                                           help="the colour camera's CameraInfo (default: the "
                                                "one beside --color-topic, then --intrinsics)")
    inspection_topic: str | None = option(None, metavar="TOPIC", group=BAG,
                                          help="images of the inspection spot (default: none: "
                                               "no inspection view)")
    step_topic: str | None = option(None, metavar="TOPIC", group=BAG,
                                    help="a topic whose messages mark step starts (default: "
                                         "none: --step-seconds, else perceived changes)")
    sync_tolerance: float = option(0.05, metavar="SECONDS", group=BAG,
                                   help="how near in time depth and inspection images must be "
                                        "to a colour frame, in seconds")
    models: Path | None = common.models()

    @property
    def is_bag(self) -> bool:
        """Whether the source is a ROS bag rather than a video file or a camera."""
        from recordings.sources.bags import is_bag

        return self.video is not None and is_bag(self.video)

    def __post_init__(self) -> None:
        from recordings.sources.bags import mcap_kind

        if (self.video is None) == (self.camera is None):
            raise ValueError("give exactly one source: a video file, a bag or --camera INDEX; "
                             f"got video={self.video}, camera={self.camera}")
        bag_options = {"--color-topic": self.color_topic, "--depth-topic": self.depth_topic,
                       "--camera-info-topic": self.camera_info_topic,
                       "--inspection-topic": self.inspection_topic,
                       "--step-topic": self.step_topic}
        if self.video is not None and mcap_kind(self.video) == "session":
            raise ValueError(f"{self.video} is an onionsort session already; perceive it, or "
                             "learn from it, as it is")
        given = [name for name, value in bag_options.items() if value is not None]
        if given and not self.is_bag:
            raise ValueError(f"{', '.join(given)} go with a ROS bag; {self.video or 'a camera'}"
                             " is not one (a rosbag2 folder, its .mcap or .db3 file, a .bag)")
        if self.camera_info_topic is not None and self.intrinsics is not None:
            raise ValueError("give --camera-info-topic or --intrinsics, not both: the "
                             "colour camera's intrinsics come from one of them")
        if self.step_topic is not None and self.step_seconds is not None:
            raise ValueError("give --step-topic or --step-seconds, not both")
        if not (math.isfinite(self.sync_tolerance) and self.sync_tolerance >= 0):
            raise ValueError(f"sync_tolerance must be a number of seconds >= 0; got "
                             f"{self.sync_tolerance}")
        if self.step_seconds is not None and not self.step_seconds > 0:
            raise ValueError(f"step_seconds must be > 0; got {self.step_seconds}")
        if self.debounce < 1:
            raise ValueError(f"debounce must be >= 1; got {self.debounce}")
        if self.frames_per_step < 1:
            raise ValueError(f"frames_per_step must be >= 1; got {self.frames_per_step}")
        if not self.max_seconds > 0:
            raise ValueError(f"max_seconds must be > 0; got {self.max_seconds}")
        if self.inspection is not None and (self.video is None or self.is_bag):
            raise ValueError("--inspection VIDEO goes with a video file, not a camera or a bag "
                             "(a bag's: --inspection-topic)")
        if Path(self.out).exists():
            raise FileExistsError(f"{self.out} exists; choose another --out")
