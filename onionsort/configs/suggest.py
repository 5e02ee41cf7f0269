"""The config of stage ``suggest`` (:mod:`onionsort.stages.suggest`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from onionsort.configs import documented, option

__all__ = ["SuggestConfig"]


@documented
@dataclass(frozen=True, kw_only=True)
class SuggestConfig:
    """Which learning run, and how many states to list."""

    run: Path = option(positional=True, metavar="RUN_DIR",
                       help="a folder of `onionsort learn --posterior`")
    top: int = option(5, help="states to list")

    def __post_init__(self) -> None:
        if isinstance(self.top, bool) or not isinstance(self.top, int) or self.top < 1:
            raise ValueError(f"top must be an int >= 1; got {self.top!r}")
