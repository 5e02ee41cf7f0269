"""The config of stage ``dataset`` (:mod:`onionsort.stages.dataset`)."""

from __future__ import annotations

import argparse
import re
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

from onionsort.configs import common, documented, option
from onionsort.configs.parallel import ParallelOptions

__all__ = ["DatasetConfig", "image_size", "levels"]


def levels(text: str) -> str:
    """One difficulty level or several joined by commas, for argparse ``type=``."""
    unknown = [x for x in text.split(",") if x.strip() not in common.DIFFICULTY_LEVELS]
    if unknown:
        raise argparse.ArgumentTypeError(
            f"unknown level {unknown[0].strip()!r}; the levels are "
            f"{', '.join(common.DIFFICULTY_LEVELS)}")
    return ",".join(x.strip() for x in text.split(","))


def image_size(text: str) -> str:
    """The inspection view's size ``WIDTHxHEIGHT`` in pixels, each 32 to 1920, in the 4:3
    shape of the view (its field of view is vertical: another shape would widen or narrow
    it), for argparse ``type=``."""
    if not isinstance(text, str):
        raise TypeError(f"an image size is a 'WIDTHxHEIGHT' string; got {text!r}")
    match = re.fullmatch(r"\s*([0-9]+)\s*[xX]\s*([0-9]+)\s*", text)
    if match is None:
        raise argparse.ArgumentTypeError(f"an image size is WIDTHxHEIGHT, e.g. 320x240; "
                                         f"got {text!r}")
    w, h = int(match[1]), int(match[2])
    if not (32 <= w <= 1920 and 32 <= h <= 1920):
        raise argparse.ArgumentTypeError(f"an image's width and height are 32 to 1920 pixels; "
                                         f"got {text!r}")
    if 3 * w != 4 * h:
        raise argparse.ArgumentTypeError(f"the inspection view keeps its 4:3 shape (e.g. "
                                         f"320x240); got {text!r}")
    return f"{w}x{h}"


@documented
@dataclass(frozen=True, kw_only=True)
class DatasetConfig(ParallelOptions):
    """What to render; an existing dataset in ``out`` is never overwritten.

    ``occlusion`` is 0.3 by default: the classifier must see many occluded steps. A mix of
    ``difficulty`` levels has its sessions and robot line-ups take them in turn;
    ``randomize_look`` (:mod:`robot.look`) is a knob beside the levels, which stay as they
    are. The sessions and the line-ups are the pieces, each rendered from its own seed into
    images named after it (``s0003_0012.png``, ``l0001_0004.png``).
    """

    frames: int = option(3000, help="frames in all")
    out: Path = option(help="new dataset folder")
    seed: int = common.seed()
    occlusion: float = common.occlusion(0.3)
    steps_per_session: int = common.steps_per_session()
    frames_per_step: int = common.frames_per_step()
    val: float = option(0.15, help="share of sessions for val")
    test: float = option(0.15, help="share of sessions for test")
    robot_onions: int = option(120, help="onions the Sawyer holds up to its inspection camera, "
                                         "in line-ups of 10 split like the sessions; 0 for "
                                         "none")
    robot_views: int = option(8, help="views the Sawyer takes of each of them")
    difficulty: str = option("clean", type=levels,
                             help="perception difficulty of the world: one of "
                                  f"{', '.join(common.DIFFICULTY_LEVELS)}, or several joined "
                                  "by commas for a mix whose sessions take the levels in turn")
    randomize_look: bool = option(False, help="draw each session's and line-up's light, "
                                              "surface colours and camera exposure and white "
                                              "balance from its seed (training data across "
                                              "cameras; without it, one look for all)")
    #: The default is the size of ``robot.simulation.INSPECTION_CAMERA`` (a test holds them
    #: together).
    inspection_size: str = option("160x120", type=image_size, metavar="WIDTHxHEIGHT",
                                  help="size of the sorter's inspection view in pixels, each "
                                       "32 to 1920, 4:3 (the same view at another "
                                       "resolution; the Sawyer's camera is its own)")
    #: Measure the rot each inspection view shows (the inspection classifier's labels; one more
    #: render of each view). Calibration needs none.
    rot_labels: bool = True
    cli_help: ClassVar[dict[str, str]] = {"pieces": "sessions and line-ups"}

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "out", Path(self.out))
        for level in self.levels:
            common.check_difficulty(level)
        if self.frames < 1:
            raise ValueError(f"frames must be >= 1; got {self.frames}")
        if self.robot_onions < 0:
            raise ValueError(f"robot_onions must be >= 0; got {self.robot_onions}")
        if self.robot_views < 1:
            raise ValueError(f"robot_views must be >= 1; got {self.robot_views}")
        try:
            object.__setattr__(self, "inspection_size", image_size(self.inspection_size))
        except argparse.ArgumentTypeError as err:
            raise ValueError(f"inspection_size: {err}") from None

    @property
    def inspection_pixels(self) -> tuple[int, int]:
        """The sorter's inspection view's (width, height) in pixels."""
        w, h = self.inspection_size.split("x")
        return int(w), int(h)

    @property
    def levels(self) -> list[str]:
        """The difficulty levels, in the order sessions and line-ups take them."""
        return [level.strip() for level in self.difficulty.split(",")]
