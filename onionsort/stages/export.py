"""Stage ``export``: a session becomes a file other tools read.

``ros2``: a rosbag2 folder (``metadata.yaml`` and one MCAP or SQLite 3 file of CDR-serialised
ROS 2 Humble messages) that ``ros2 bag play`` replays and the ROS tools list; the topics are
those of :mod:`recordings.sources.ros_export`. The folder is written under a temporary name and
renamed once complete; an existing output is refused.

Example::

    from onionsort.stages import ExportConfig, export_session
    export_session(ExportConfig(session=Path("runs/rec/session_000.mcap"),
                                out=Path("runs/rec/session_000_ros2")))
"""

from __future__ import annotations

from pathlib import Path

from onionsort.configs.export import EXPORT_FORMATS, ROS2_STORAGES, ExportConfig
from onionsort.stages.base import check_output_folder, log_config

__all__ = ["EXPORT_FORMATS", "ROS2_STORAGES", "ExportConfig", "export_session"]

def export_session(config: ExportConfig):
    """Export the session; return the :class:`recordings.sources.ros_export.ExportSummary`."""
    from recordings.sources.ros_export import export_ros2

    log_config("export", config)
    check_output_folder(Path(config.out).parent, f"the folder of --out {config.out}")
    return export_ros2(config.session, config.out, raw_images=config.raw_images,
                       storage=config.storage)
