"""The configs of stages ``calibrate`` and ``eval-perception``
(:mod:`onionsort.stages.calibrate`), and ``compare-perception``
(:mod:`onionsort.stages.compare_perception`)."""

from __future__ import annotations

import argparse
import numbers
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

from onionsort.configs import common, documented, option
from onionsort.configs.parallel import TORCH_THREADS, ParallelOptions

__all__ = ["CalibrateConfig", "PerceptionCompareConfig", "PerceptionEvalConfig", "camera_seeds",
           "check_camera_seeds", "check_camera_shift"]


def check_camera_shift(seed, name: str = "camera_shift") -> None:
    """Refuse a ``camera_shift`` (or the option ``name``) that is not a seed, an int >= 0
    (numpy's ints are ints)."""
    if not isinstance(seed, numbers.Integral) or isinstance(seed, bool) or seed < 0:
        raise ValueError(f"{name} must be a seed, an int >= 0; got {seed!r}")


def check_camera_seeds(seeds, name: str = "camera_shift") -> tuple[int, ...]:
    """``seeds`` as a tuple of ints: one seed, or a list of them, each an int >= 0, none twice
    and at least one; else a ``ValueError`` that names the option (``name``) and the first bad
    one."""
    if isinstance(seeds, numbers.Integral) and not isinstance(seeds, bool):
        seeds = (seeds,)
    if isinstance(seeds, (str, bytes)) or not hasattr(seeds, "__iter__"):
        raise ValueError(f"{name} must be seeds, ints >= 0; got {seeds!r}")
    seeds = tuple(seeds)
    if not seeds:
        raise ValueError(f"{name} must name at least one seed; got none")
    for seed in seeds:
        check_camera_shift(seed, name)
    repeated = next((s for i, s in enumerate(seeds) if s in seeds[:i]), None)
    if repeated is not None:
        raise ValueError(f"{name} names seed {repeated} twice; got {list(seeds)}")
    return tuple(int(s) for s in seeds)


def camera_seeds(text: str) -> tuple[int, ...]:
    """``--camera-shift``'s text, for argparse ``type=``: comma-separated ints (checked by
    :func:`check_camera_seeds` when the config is made)."""
    parts = [x.strip() for x in text.split(",")]
    try:
        return tuple(int(x) for x in parts)
    except ValueError:
        bad = next(x for x in parts if not x.lstrip("-").isdigit())
        raise argparse.ArgumentTypeError(
            f"expected comma-separated seeds, ints >= 0 (e.g. 11,12,13); got {bad!r} in "
            f"{text!r}") from None


@documented
@dataclass(frozen=True, kw_only=True)
class CalibrateConfig(ParallelOptions):
    """Where to measure perception and where to write the calibration.

    ``data`` is a labelled dataset from ``onionsort dataset``, held out (not trained on);
    ``out`` gets ``calibration.json``, ``observation_model.npz`` and ``confusion.png``. Each of
    the dataset's sessions is a piece.
    """

    data: Path = option(help="labelled dataset folder")
    split: str = option("test", help="the held-out split to use: train, val, test or all")
    out: Path = option(help="folder for the calibration")
    smoothing: float = option(1.0, help="additive smoothing of the confusion counts")
    depth: bool = option(True, help="measure the classifier on colour alone (for sessions "
                                    "without depth)")
    inspection: bool = option(True, help="measure without the inspection view (for a video "
                                         "imported without --inspection; the onion's class "
                                         "is then unobserved)")
    overwrite: bool = option(False, help="replace a calibration.json already in --out")
    models: Path | None = common.models()
    device: str = common.device()
    cli_help: ClassVar[dict[str, str]] = {"pieces": "dataset's sessions"}
    #: Measuring a session is mostly the classifiers' work, on torch's threads.
    piece_threads: ClassVar[int] = TORCH_THREADS

    def __post_init__(self) -> None:
        super().__post_init__()
        common.check_device(self.device)
        if self.smoothing < 0:
            raise ValueError(f"smoothing must be >= 0; got {self.smoothing}")


@documented
@dataclass(frozen=True)
class PerceptionEvalConfig:
    """A dataset split to measure the perception models on: the detector, the state
    classifier and the inspection; ``camera_shift`` draws the other cameras, once per seed
    (:class:`~onionsort.stages.cameras.SessionCameras`; one seed, an int, is a list of
    one)."""

    data: Path = option(help="labelled dataset folder")
    split: str = option("test", help="split to evaluate on: train, val, test or all")
    depth: bool = option(True, help="classifier on colour alone")
    inspection: bool = option(True, help="without the inspection view")
    views: int | None = option(None, help="fuse the Sawyer's first VIEWS views of each onion "
                                          "(default: all the dataset holds)")
    plots: Path | None = option(None, metavar="DIR",
                                help="draw the inspection's precision-recall curves into DIR "
                                     "(default: none)")
    camera_shift: tuple[int, ...] | None = option(
        None, metavar="SEEDS", type=camera_seeds,
        help="measure through other cameras too, once per seed of SEEDS (ints >= 0, "
             "comma-separated: 11,12,13), and print each figure unchanged, through each seed's "
             "cameras, their mean and the worst drop (default: none)")
    one_camera: bool = option(False, help="with --camera-shift: one camera per seed for every "
                                          "session and line-up (a lab's one camera), not one "
                                          "camera a session")
    models: Path | None = common.models()
    device: str = common.device()

    def __post_init__(self) -> None:
        common.check_device(self.device)
        if self.camera_shift is not None:
            object.__setattr__(self, "camera_shift", check_camera_seeds(self.camera_shift))
        elif self.one_camera:
            raise ValueError("one_camera needs camera_shift: the seeds of the cameras")
        if self.views is not None and self.views < 1:
            raise ValueError(f"views must be >= 1; got {self.views}")


@documented
@dataclass(frozen=True, kw_only=True)
class PerceptionCompareConfig:
    """Two sets of models' ``eval-perception --json`` results, one file per dataset: the
    baseline's (``base``) and the candidate's (``candidate``), on the same datasets in the same
    order."""

    base: tuple[Path, ...] = option(type=Path, action="append", metavar="FILE.json",
                                    help="the baseline models' `eval-perception --json` result "
                                         "on one dataset (repeat it, once per dataset)")
    candidate: tuple[Path, ...] = option(type=Path, action="append", metavar="FILE.json",
                                         help="the candidate models' result on the same "
                                              "dataset (repeat it, in --base's order)")

    def __post_init__(self) -> None:
        for name in ("base", "candidate"):
            value = getattr(self, name)
            value = (value,) if isinstance(value, str | Path) else tuple(value or ())
            if not value:
                raise ValueError(f"{name} must name at least one result file; got none")
            object.__setattr__(self, name, tuple(Path(v) for v in value))
        if len(self.base) != len(self.candidate):
            raise ValueError(f"give one --candidate result per --base one, in the same order; "
                             f"got {len(self.base)} --base and {len(self.candidate)} "
                             f"--candidate")
