"""The config of stage ``perceive`` (:mod:`onionsort.stages.perceive`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

from onionsort.configs import common, option
from onionsort.configs.parallel import TORCH_THREADS, ParallelOptions

__all__ = ["PerceiveConfig"]


@dataclass(frozen=True, kw_only=True)
class PerceiveConfig(ParallelOptions):
    """Which sessions to perceive, with which models.

    Attributes
    ----------
    sessions : tuple of Path
        Session files (``.mcap``); each gets the perception topics in place.
    replace : bool
        Perceive sessions that already hold perception topics again.
    models : Path or None
        Folder with ``state_classifier.pt``, ``detector.pt`` and
        ``inspection_classifier.pt`` (None: the shipped models).
    device : str
        Where torch runs the models: ``auto`` (CUDA when present), ``cpu`` or ``cuda``.
    batch_size : int
        Frames per detector batch.
    executor, workers, ray_address
        Where the sessions are perceived (:class:`~onionsort.configs.parallel.ParallelOptions`):
        each is a piece.
    """

    sessions: tuple[Path, ...] = option(positional=True, nargs="+", metavar="SESSION.mcap",
                                        help=None)
    replace: bool = option(False, help="perceive sessions that already hold perception "
                                       "topics again")
    models: Path | None = common.models()
    device: str = common.device()
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
