"""The config of stage ``report`` (:mod:`onionsort.stages.report`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from onionsort.configs import documented, option

__all__ = ["ReportConfig"]


@documented
@dataclass(frozen=True, kw_only=True)
class ReportConfig:
    """Which run folder to report on: ``report.md`` (and ``report_pr.png`` where there are
    sorting counts) go into it."""

    run: Path = option(positional=True, metavar="RUN_DIR",
                       help="a folder of `onionsort demo`, `experiment`, `learn` or "
                            "`evaluate`")

    def __post_init__(self) -> None:
        if not isinstance(self.run, str | Path):
            raise TypeError(f"run must be a path; got {type(self.run).__name__}")
        object.__setattr__(self, "run", Path(self.run))
