"""The config of stage ``perceive`` (:mod:`onionsort.stages.perceive`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

from onionsort.configs import common, documented, option
from onionsort.configs.parallel import TORCH_THREADS, ParallelOptions

__all__ = ["PerceiveConfig"]


@documented
@dataclass(frozen=True, kw_only=True)
class PerceiveConfig(ParallelOptions):
    """Which sessions to perceive (``.mcap`` files, each of which gets the perception topics in
    place, a piece each), with which models."""

    sessions: tuple[Path, ...] = option(positional=True, nargs="+", metavar="SESSION.mcap",
                                        help="recorded or imported sessions")
    replace: bool = option(False, help="perceive sessions that already hold perception "
                                       "topics again")
    models: Path | None = common.models()
    device: str = common.device()
    #: Frames per detector batch.
    batch_size: int = 32
    cli_help: ClassVar[dict[str, str]] = {"pieces": "sessions"}
    #: Perceiving a session is mostly the networks' work, on torch's threads.
    piece_threads: ClassVar[int] = TORCH_THREADS

    def __post_init__(self) -> None:
        super().__post_init__()
        common.check_device(self.device)
        common.check_session_files(self.sessions)
        if self.batch_size < 1:
            raise ValueError(f"batch_size must be >= 1; got {self.batch_size}")
