"""The config of stage ``export`` (:mod:`onionsort.stages.export`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from onionsort.configs import documented, option

__all__ = ["EXPORT_FORMATS", "ROS2_STORAGES", "ExportConfig"]

#: What a session can be exported as.
EXPORT_FORMATS = ("ros2",)
#: :data:`recordings.sources.ros_export.STORAGES`, repeated so that building the parser does
#: not import the recordings (a test checks they agree).
ROS2_STORAGES = ("mcap", "sqlite3")


@documented
@dataclass(frozen=True, kw_only=True)
class ExportConfig:
    """Which session, as what, and where; an existing ``out`` is refused."""

    session: Path = option(positional=True, metavar="SESSION", help="a session file (.mcap)")
    format: str = option("ros2", choices=EXPORT_FORMATS,
                         help="what to write: ros2, a rosbag2 folder (the only format for "
                              "now)")
    out: Path = option(help="the folder to create (refused if it exists)")
    raw_images: bool = option(False, help="decoded rgb8 sensor_msgs/Image instead of the "
                                          "session's JPEG and PNG bytes as CompressedImage")
    storage: str = option("mcap", choices=ROS2_STORAGES,
                          help="the rosbag2 storage plugin: mcap or sqlite3")

    def __post_init__(self) -> None:
        if self.format not in EXPORT_FORMATS:
            raise ValueError(f"format must be one of {', '.join(EXPORT_FORMATS)}; got "
                             f"{self.format!r}")
        if self.storage not in ROS2_STORAGES:
            raise ValueError(f"storage must be one of {', '.join(ROS2_STORAGES)}; got "
                             f"{self.storage!r}")
        if not isinstance(self.raw_images, bool):
            raise TypeError(f"raw_images must be a bool; got {type(self.raw_images).__name__}")
        if Path(self.out).exists():
            raise FileExistsError(f"{self.out} exists; choose another --out or remove it")
