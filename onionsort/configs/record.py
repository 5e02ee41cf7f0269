"""The config of stage ``record`` (:mod:`onionsort.stages.record`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

from onionsort.configs import common, documented, option
from onionsort.configs.parallel import ParallelOptions

__all__ = ["RecordConfig"]


@documented
@dataclass(frozen=True, kw_only=True)
class RecordConfig(ParallelOptions):
    """How many sessions to simulate, how, and where to write them.

    Each session is a piece, simulated from its own seed (drawn from ``seed``): the sessions
    are the same whatever runs them. ``rerun`` is an ``.rrd`` path, ``"spawn"`` (a local
    viewer) or a viewer URL; ``resume``: see :mod:`onionsort.stages.record`.
    """

    sessions: int = option(12, help="sessions to record")
    out: Path = option(help="folder for the .mcap files")
    seed: int = common.seed()
    occlusion: float = common.occlusion(0.2)
    steps_per_session: int = common.steps_per_session()
    frames_per_step: int = common.frames_per_step()
    width: int = option(320, help="camera width in pixels")
    height: int = option(240, help="camera height in pixels")
    overwrite: bool = option(False, exclusive="again",
                             help="replace existing session files in --out")
    resume: bool = option(False, exclusive="again",
                          help="keep the complete sessions in --out and record the others "
                               "(interrupted ones again, from their own seeds)")
    rerun: Path | str | None = option(None, type=Path, metavar="FILE.rrd", exclusive="viewer",
                                      help="also log every session to this Rerun file "
                                           "(default: none)")
    connect: str | None = common.connect("every session")
    difficulty: str = common.difficulty()
    cli_help: ClassVar[dict[str, str]] = {"pieces": "sessions"}

    def __post_init__(self) -> None:
        super().__post_init__()
        common.check_difficulty(self.difficulty)
        if self.resume and self.overwrite:
            raise ValueError("resume keeps the complete sessions in --out and overwrite "
                             "replaces them all; give --resume or --overwrite, not both")
        for name in ("sessions", "steps_per_session", "frames_per_step"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1; got {getattr(self, name)}")
        if not 0.0 <= self.occlusion <= 1.0:
            raise ValueError(f"occlusion must be in [0, 1]; got {self.occlusion}")
        if min(self.width, self.height) < 8:
            raise ValueError(f"width and height must be >= 8; got {self.width}x{self.height}")
        if self.connect is not None:
            from recordings.rerun.common import check_viewer_url

            check_viewer_url(self.connect)
            if str(self.rerun) == "spawn":
                raise ValueError("spawn starts a local viewer and connect streams to another; "
                                 "give --spawn or --connect, not both")
