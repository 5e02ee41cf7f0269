"""The configs of stages ``label export``, ``label import`` (:mod:`onionsort.stages.label`)
and ``label select`` (:mod:`onionsort.stages.label_select`)."""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

from onionsort.configs import common, documented, option
from onionsort.configs.common import IMPORT_FORMATS, LABEL_FORMATS, SELECT_FORMATS, SELECT_SAMPLES

__all__ = ["IMPORT_FORMATS", "LABEL_FORMATS", "SELECT_FORMATS", "LabelExportConfig",
           "LabelImportConfig", "LabelSelectConfig", "check_format", "classes"]


def check_format(fmt: str, formats: tuple[str, ...] = LABEL_FORMATS) -> None:
    """Refuse a labelled-set format that is not one of ``formats``."""
    if fmt not in formats:
        raise ValueError(f"format must be one of {formats}; got {fmt!r}")


def classes(text: str) -> dict[str, str]:
    """``class=NAME`` pairs joined by commas, for argparse ``type=``."""
    out = {}
    for part in filter(None, (x.strip() for x in text.split(","))):
        cls, sep, name = part.partition("=")
        if not sep or cls.strip() not in ("good", "blemished") or not name.strip():
            raise argparse.ArgumentTypeError(
                f"expected good=NAME,blemished=NAME; got {part!r}")
        out[cls.strip()] = name.strip()
    return out


@documented
@dataclass(frozen=True, kw_only=True)
class LabelExportConfig:
    """``onionsort label export``: the dataset folder, the output folder (new) and the
    layout (``coco`` or ``yolo``)."""

    data: Path = option(positional=True, metavar="DATASET", help="a dataset folder")
    format: str = option("coco", choices=LABEL_FORMATS, required=True,
                         help="coco (COCO 2017 layout) or yolo (Ultralytics layout)")
    out: Path = option(help="a new folder")

    def __post_init__(self) -> None:
        object.__setattr__(self, "data", Path(self.data))
        object.__setattr__(self, "out", Path(self.out))
        check_format(self.format)


@documented
@dataclass(frozen=True, kw_only=True)
class LabelImportConfig:
    """``onionsort label import``: what to read and where to write it.

    ``source`` is in COCO or YOLO layout (:mod:`recordings.labels.coco`,
    :mod:`recordings.labels.yolo`), or Label Studio's JSON export beside the images, its state
    choices the state labels (:func:`recordings.labels.labelstudio.read_export`); ``states``:
    :mod:`recordings.labels.states_csv`.
    A depth image matches the image ``NAME.*`` as ``depth/<split>/NAME.png`` or
    ``depth/NAME.png``; frames without depth are read by the colour-only models. A class
    that ``classes`` does not name keeps its own name.
    """

    source: Path = option(positional=True, metavar="DIR", help="the labelled image set")
    format: str = option("coco", choices=IMPORT_FORMATS, required=True,
                         help="coco (COCO 2017, Roboflow, CVAT, Label Studio), yolo "
                              "(Ultralytics, Roboflow) or labelstudio (Label Studio's JSON "
                              "export: boxes and state choices)")
    states: Path | None = option(None, metavar="FILE.csv",
                                 help="the state labels; frames without a row are box-only "
                                      "(default: DIR/states.csv where there is one)")
    depth: Path | None = option(None, metavar="DIR",
                                help="16-bit PNG depth in millimetres, matched by file name "
                                     "(default: DIR/depth where there is one)")
    inspection: Path | None = option(None, metavar="DIR",
                                     help="the inspection views, in the same format with their "
                                          "own states.csv (default: DIR/inspection where there "
                                          "is one)")
    classes: dict = option(default_factory=dict, type=classes,
                           metavar="good=NAME,blemished=NAME",
                           help="the set's names of the dataset's classes (default: good, "
                                "blemished)")
    out: Path = option(help="a new dataset folder")
    #: Share of sessions for val where the set has no splits (as ``onionsort dataset`` splits
    #: its sessions).
    val: float = 0.15
    #: Share of sessions for test, likewise.
    test: float = 0.15

    def __post_init__(self) -> None:
        from recordings.labels.dataset import CLASSES

        for name in ("source", "out", "states", "depth", "inspection"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, Path(getattr(self, name)))
        check_format(self.format, IMPORT_FORMATS)
        unknown = [k for k in self.classes if k not in CLASSES]
        if unknown:
            raise ValueError(f"classes maps {unknown[0]!r}, which is not a class of the "
                             f"dataset ({', '.join(CLASSES)})")
        object.__setattr__(self, "classes", dict(self.classes))


@documented
@dataclass(frozen=True, kw_only=True)
class LabelSelectConfig:
    """``onionsort label select``: the sessions, how many frames, the output folder (new),
    its format (``coco`` or ``labelstudio``), how steps are chosen (``sample``: the least
    sure first, or uniformly at random from ``seed``), whether to score the choice against the
    sessions' truth (``recall``), the models (None: the shipped ones) and where torch runs
    them."""

    sessions: tuple[Path, ...] = option(positional=True, nargs="+", metavar="SESSION",
                                        help="recorded sessions (.mcap)")
    frames: int = option(200, required=True, metavar="N",
                         help="how many frames to choose (whole steps, in rounds over the "
                              "sessions)")
    format: str = option("coco", choices=SELECT_FORMATS,
                         help="coco (images, annotations with scores, states.csv; what label "
                              "import reads back) or labelstudio (tasks.json with predictions "
                              "and labeling_config.xml)")
    out: Path = option(help="a new folder")
    sample: str = option("uncertain", choices=SELECT_SAMPLES,
                         help="uncertain (the steps the models are least sure of: frames "
                              "worth labelling for training) or random (steps drawn uniformly "
                              "with --seed: an unbiased sample, for calibrating on held-out "
                              "sessions)")
    seed: int = common.seed("the random sample's seed")
    recall: bool = option(False, help="sessions that carry ground truth: also count the steps "
                                      "whose state guess is wrong and how many of them the "
                                      "frames chosen hold (the truth is read after choosing, "
                                      "to score it only)")
    models: Path | None = common.models()
    device: str = common.device()

    def __post_init__(self) -> None:
        object.__setattr__(self, "sessions", tuple(Path(p) for p in self.sessions))
        object.__setattr__(self, "out", Path(self.out))
        common.check_device(self.device)
        if self.frames < 1:
            raise ValueError(f"frames must be >= 1; got {self.frames}")
        if self.format not in SELECT_FORMATS:
            raise ValueError(f"format must be one of {SELECT_FORMATS}; got {self.format!r}")
        if self.sample not in SELECT_SAMPLES:
            raise ValueError(f"sample must be one of {SELECT_SAMPLES}; got {self.sample!r}")
        common.check_session_files(self.sessions)
