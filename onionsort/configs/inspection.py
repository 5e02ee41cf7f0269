"""The configs of the inspection's training stages, ``train inspection`` and ``train
robot-fusion`` (:mod:`onionsort.stages.inspection`)."""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

from onionsort.configs import common, documented, option, train
from onionsort.configs.common import CALIBRATION_FORMS, INSPECTION_CAMERAS

__all__ = ["CALIBRATION_FORMS", "INSPECTION_CAMERAS", "TRAINING_CROPS",
           "FusionCalibrationConfig", "InspectionTrainStageConfig", "level_forms",
           "level_weights"]


TRAINING_CROPS = ("labelled", "detected")  # where train inspection cuts its training crops


def level_weights(text: str) -> dict[str, float]:
    """``level=weight`` pairs joined by commas, for argparse ``type=``."""
    out = {}
    for level, weight in _level_pairs(text, "level=weight", "clean=2").items():
        try:
            out[level] = float(weight)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected level=weight pairs, e.g. clean=2; got {f'{level}={weight}'!r}"
            ) from None
        if not out[level] > 0:
            raise argparse.ArgumentTypeError(f"a level's weight must be > 0; got "
                                             f"{level}={weight}")
    return out


def level_forms(text: str) -> dict[str, str]:
    """``level=form`` pairs joined by commas (forms of :data:`CALIBRATION_FORMS`), for
    argparse ``type=``."""
    out = _level_pairs(text, "level=form", "hard=powers")
    for level, form in out.items():
        if form not in CALIBRATION_FORMS:
            raise argparse.ArgumentTypeError(
                f"unknown form {form!r} for {level!r}; the forms are "
                f"{', '.join(CALIBRATION_FORMS)}")
    return out


def _level_pairs(text: str, shape: str, example: str) -> dict[str, str]:
    """The ``level=value`` pairs of ``text`` (commas between them), each level a known one."""
    out = {}
    for part in filter(None, (x.strip() for x in text.split(","))):
        level, sign, value = part.partition("=")
        if level not in common.DIFFICULTY_LEVELS:
            raise argparse.ArgumentTypeError(
                f"unknown level {level!r} in {text!r}; the levels are "
                f"{', '.join(common.DIFFICULTY_LEVELS)}")
        if not sign:
            raise argparse.ArgumentTypeError(f"expected {shape} pairs, e.g. {example}; got "
                                             f"{part!r}")
        out[level] = value
    return out


@documented
@dataclass(frozen=True, kw_only=True)
class InspectionTrainStageConfig(train.TrainOptions):
    """``onionsort train inspection``: dataset folders (their splits pooled), run folder,
    hyperparameters.

    A training view counts its dataset's ``data_weights`` times its level's weight. With
    ``through_cameras`` each training view is also seen through the camera its session or
    line-up has under ``eval-perception --camera-shift SEED``, once per seed (and each
    validation view through the first seed's). With ``log_odds_data`` the map the ``log-odds``
    fusion reads (Platt's, from a view's logit to P(its onion is blemished)) is fitted on every
    view of those held-out datasets, both cameras', instead of on the validation views.
    With ``crops`` ``"detected"`` the training crops are cut round the box ``detector`` finds,
    not the labelled one. ``camera`` ``"both"`` and ``"sorter"`` (the sorter's views alone) write
    :data:`~onionsort.stages.models.INSPECTION_FILE`, ``"robot"``
    :data:`~onionsort.stages.models.ROBOT_INSPECTION_FILE`; a smaller ``lr`` suits
    fine-tuning from ``init``.
    """

    epochs: int = option(30, help=train.EPOCHS)
    batch_size: int = option(128, help=train.BATCH_SIZE)
    detector: Path | None = option(None, help="folder of the detector.pt that finds the onion "
                                              "in the validation views, and with --crops "
                                              "detected in the training views, its "
                                              "robot_detector.pt in the Sawyer's where it has "
                                              "one (default: the shipped one)")
    crops: str = option("labelled", choices=TRAINING_CROPS,
                        help="where each training crop is cut: round the view's labelled box, "
                             "or round the box --detector finds there, the framing inspection "
                             "then reads (views it finds no onion in are left out)")
    level_weights: dict = option(default_factory=dict, type=level_weights,
                                 help="weights of difficulty levels, e.g. clean=2,hard=1 "
                                      "(default: 1 each)")
    fusion: str | None = common.fusion("the classifier's fusion rule (default: the one of "
                                       "lower log-loss on the validation onions)")
    camera: str = option("both", choices=INSPECTION_CAMERAS,
                         help="whose views to learn from: both (the sorter's and the robot's; "
                              "writes inspection_classifier.pt, which both read), robot (the "
                              "Sawyer's only; writes robot_inspection_classifier.pt, which its "
                              "inspection then reads instead) or sorter (the sorter's only; "
                              "writes inspection_classifier.pt, validated and calibrated on the "
                              "sorter's views)")
    visibility: float | None = option(None, help="the chance that a view of a blemished onion "
                                                 "shows its rot, as noisy-or fusion assumes it "
                                                 "(default: the share measured on the "
                                                 "training views)")
    init: Path | None = train.init("an inspection_classifier.pt")
    lr: float = train.lr(3e-3)
    through_cameras: tuple[int, ...] = train.through_cameras("inspection view")
    log_odds_data: tuple[Path, ...] | None = option(
        None, type=Path, action="append", metavar="DATA",
        help="held-out dataset folder (repeat it to pool several) whose views, the sorter's and "
             "the robot's, every split, fit the map the log-odds fusion reads (from a view's "
             "logit to P(its onion is blemished)) instead of the validation views; never data "
             "you then measure on (default: the validation views)")

    def __post_init__(self) -> None:
        from perception.fusion import FUSION_RULES

        super().__post_init__()
        object.__setattr__(self, "log_odds_data",
                           tuple(Path(d) for d in self.log_odds_data or ()))
        training = {d.resolve() for d in self.data}
        for folder in self.log_odds_data:
            if folder.resolve() in training:
                raise ValueError(f"log_odds_data {folder} is also training data; the map is "
                                 "fitted on held-out views")
        train.check_lr(self.lr)
        train.check_through_cameras(self)
        if self.fusion is not None and self.fusion not in FUSION_RULES:
            raise ValueError(f"fusion must be one of {FUSION_RULES}; got {self.fusion!r}")
        if self.visibility is not None and not 0.0 < self.visibility <= 1.0:
            raise ValueError(f"visibility must be in (0, 1]; got {self.visibility}")
        if self.crops not in TRAINING_CROPS:
            raise ValueError(f"crops must be one of {TRAINING_CROPS}; got {self.crops!r}")
        if self.camera not in INSPECTION_CAMERAS:
            raise ValueError(f"camera must be one of {INSPECTION_CAMERAS}; got "
                             f"{self.camera!r}")
        for level, weight in self.level_weights.items():
            if not weight > 0:
                raise ValueError(f"level weight of {level!r} must be > 0; got {weight}")


@documented
@dataclass(frozen=True, kw_only=True)
class FusionCalibrationConfig:
    """``onionsort train robot-fusion``: the held-out robot onions whose fused P(blemished) fit
    the calibration, and where it goes (``views`` None: the robot's
    :data:`~robot.inspection_poses.INSPECTION_VIEWS`)."""

    data: Path | tuple[Path, ...] = train.data("held-out dataset folder with robot onions "
                                               "(repeat it to pool several); never the data "
                                               "the calibration is then measured on")
    split: str = option("all", choices=("train", "val", "test", "all"),
                        help="the split whose robot onions fit it")
    views: int | None = option(None, help="the first VIEWS views of each onion (default: as "
                                          "many as the robot takes)")
    form: str = option("log", choices=CALIBRATION_FORMS,
                       help="log: a slope each side of the evidence 0 on log(1 + |evidence|); "
                            "slopes: on the evidence itself; powers: on |evidence| to a power "
                            "each side fits too")
    by_level: bool = option(False, help="also fit each difficulty level's own calibration on "
                                        "that level's onions (every level needs good and "
                                        "blemished ones); the robot on a line of that level "
                                        "applies it, the pooled one elsewhere")
    level_forms: dict = option(default_factory=dict, type=level_forms,
                               help="the form of some levels' own calibrations, with "
                                    "--by-level, e.g. hard=powers (default: --form for every "
                                    "level and the pooled one)")
    out: Path = option(help="folder to write robot_fusion_calibration.json into (the models "
                            "folder, for the robot to apply it)")
    models: Path | None = common.models()
    device: str = common.device()

    def __post_init__(self) -> None:
        data = (self.data,) if isinstance(self.data, str | Path) else tuple(self.data)
        if not data:
            raise ValueError("data must name at least one dataset folder; got none")
        object.__setattr__(self, "data", tuple(Path(d) for d in data))
        object.__setattr__(self, "out", Path(self.out))
        common.check_device(self.device)
        if self.split not in ("train", "val", "test", "all"):
            raise ValueError(f"split must be train, val, test or all; got {self.split!r}")
        if self.views is not None and (isinstance(self.views, bool)
                                       or not isinstance(self.views, int) or self.views < 1):
            raise ValueError(f"views must be an int >= 1; got {self.views!r}")
        if self.level_forms and not self.by_level:
            raise ValueError("level_forms needs by_level: only a level's own calibration can "
                             "take a form of its own")
        for level, form in self.level_forms.items():
            if level not in common.DIFFICULTY_LEVELS or form not in CALIBRATION_FORMS:
                raise ValueError(f"level_forms must map levels of {common.DIFFICULTY_LEVELS} "
                                 f"to forms of {CALIBRATION_FORMS}; got {level!r}: {form!r}")
