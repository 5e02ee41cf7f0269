"""The config of ``score`` (:func:`onionsort.stages.lineup.score`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from onionsort.configs import documented, option

__all__ = ["ScoreConfig"]


@documented
@dataclass(frozen=True, kw_only=True)
class ScoreConfig:
    """Which tally to count against which truth."""

    tally: Path = option(positional=True, metavar="TALLY.csv",
                         help="a tally: lineup, index, fate (bin, line, tray), call, "
                              "p_blemished, deferred (`evaluate` writes tally.csv; a person "
                              "who counted the bins writes one with call and p_blemished "
                              "empty)")
    truth: Path = option(metavar="FILE.csv",
                         help="each onion's class: lineup, index, class (good or blemished)")

    def __post_init__(self) -> None:
        for name in ("tally", "truth"):
            value = getattr(self, name)
            if not isinstance(value, str | Path):
                raise TypeError(f"{name} must be a path; got {type(value).__name__}")
            object.__setattr__(self, name, Path(value))
