"""Stage ``export``: a session becomes a file other tools read.

``ros2``: a rosbag2 folder (``metadata.yaml`` and one MCAP or SQLite 3 file of CDR-serialised
ROS 2 Humble messages) that ``ros2 bag play`` replays and the ROS tools list; the topics are
those of :mod:`recordings.ros_export`. The folder is written under a temporary name and renamed
once complete; an existing output is refused.

Example::

    from onionsort.stages import ExportConfig, export_session
    export_session(ExportConfig(session=Path("runs/rec/session_000.mcap"),
                                out=Path("runs/rec/session_000_ros2")))
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from onionsort.stages.base import check_output_folder, log_config

__all__ = ["EXPORT_FORMATS", "ROS2_STORAGES", "ExportConfig", "export_session"]

#: What a session can be exported as.
EXPORT_FORMATS = ("ros2",)
#: :data:`recordings.ros_export.STORAGES`, repeated so that building the parser does not import
#: the recordings (a test checks they agree).
ROS2_STORAGES = ("mcap", "sqlite3")


@dataclass(frozen=True)
class ExportConfig:
    """Which session, as what, and where.

    Attributes
    ----------
    session : Path
        The session file (``.mcap``).
    out : Path
        The folder to create; an existing one is refused.
    format : str
        One of :data:`EXPORT_FORMATS`.
    raw_images : bool
        Write decoded ``rgb8`` images instead of the session's JPEG and PNG bytes.
    storage : str
        The rosbag2 storage plugin, one of :data:`ROS2_STORAGES`.
    """

    session: Path
    out: Path
    format: str = "ros2"
    raw_images: bool = False
    storage: str = "mcap"

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


def export_session(config: ExportConfig):
    """Export the session; return the :class:`recordings.ros_export.ExportSummary`."""
    from recordings.ros_export import export_ros2

    log_config("export", config)
    check_output_folder(Path(config.out).parent, f"the folder of --out {config.out}")
    return export_ros2(config.session, config.out, raw_images=config.raw_images,
                       storage=config.storage)
