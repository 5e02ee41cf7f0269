"""Sessions on disk: MCAP writer and reader (:mod:`recordings.writer`, :mod:`recordings.reader`),
the topic layout (:mod:`recordings.schema`) and Rerun logging (:mod:`recordings.rerun_log`,
imported on demand because it loads the Rerun SDK).
"""

from recordings.reader import (
    NotASessionError,
    RecordingDamagedError,
    Session,
    open_session,
    read_demonstrations,
)
from recordings.writer import SessionWriter

__all__ = [
    "NotASessionError",
    "RecordingDamagedError",
    "Session",
    "SessionWriter",
    "open_session",
    "read_demonstrations",
]
