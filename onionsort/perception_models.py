"""The perception models a stage runs: the detector, the state classifier and the inspection
classifier (and, where the folder has them, the Sawyer's own detector and inspection classifier,
which read the robot's views instead of the shared ones), from one folder.

Loading them imports torch and the models, never the stages, the simulator or the writers: a
robot's own process loads them so (:mod:`onionsort.policy`). The stages import them from
:mod:`onionsort.stages.models`.

The default models ship with the package (``onionsort/models/``); ``onionsort train`` and
``onionsort calibrate`` reproduce them (docs/perception.md gives the commands). Every output
that perception produces records :meth:`PerceptionModels.describe` (a hash of each model), so a
calibration and the sessions it is used with can be checked to come from the same models.
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import sys
from dataclasses import dataclass, field
from pathlib import Path

from onionsort.configs.common import check_device, sorting_threshold
from onionsort.configs.parallel import TORCH_THREADS
from perception.checkpoint import checkpoint_config

__all__ = [
    "CALIBRATION_FILE",
    "DEFAULT_MODELS",
    "INSPECTION_FILE",
    "ROBOT_DETECTOR_FILE",
    "ROBOT_FUSION_FILE",
    "ROBOT_INSPECTION_FILE",
    "PerceptionModels",
    "model_mismatch",
    "read_fused_calibration",
    "resolve_device",
    "torch_threads",
]

DEFAULT_MODELS = Path(__file__).resolve().parent / "models"
CLASSIFIER_FILE = "state_classifier.pt"
DETECTOR_FILE = "detector.pt"
INSPECTION_FILE = "inspection_classifier.pt"
ROBOT_INSPECTION_FILE = "robot_" + INSPECTION_FILE  # the Sawyer's own, where there is one
ROBOT_DETECTOR_FILE = "robot_" + DETECTOR_FILE  # likewise
CALIBRATION_FILE = "calibration.json"
ROBOT_FUSION_FILE = "robot_fusion_calibration.json"
"""Beside the robot's inspection classifier: the calibration of its fused P(blemished), per
fusion rule (:func:`onionsort.stages.inspection.fit_fused_calibration`), and, where it was
fitted by level (``onionsort train robot-fusion --by-level``), each difficulty level's own
(:meth:`PerceptionModels.at_level`). Not among the hashed model files: the sorter's observation
model (``calibration.json``) does not read it."""
#: The keys of :meth:`PerceptionModels.describe` that identify the models.
HASH_KEYS = ("state_classifier_sha256", "detector_sha256", "inspection_sha256")
_FILES = {"state_classifier_sha256": CLASSIFIER_FILE, "detector_sha256": DETECTOR_FILE,
          "inspection_sha256": INSPECTION_FILE}
#: The Sawyer's own models, hashed where a folder has them (never checked against a session:
#: the sorter's observation model does not read them).
_ROBOT_FILES = {"robot_inspection_sha256": ROBOT_INSPECTION_FILE,
                "robot_detector_sha256": ROBOT_DETECTOR_FILE}


#: Models loaded by :meth:`PerceptionModels.load_cached` in this process.
_LOADED: dict[tuple, PerceptionModels] = {}


def resolve_device(device: str = "auto"):
    """The ``torch.device`` that ``device`` names: ``auto`` is CUDA when
    ``torch.cuda.is_available()``, else the CPU.

    Raises
    ------
    ValueError
        If ``device`` is not one of :data:`onionsort.configs.common.DEVICES`, or is ``cuda``
        where no CUDA device is available.
    """
    import torch

    check_device(device)
    if device == "cuda" and not torch.cuda.is_available():
        raise ValueError("device 'cuda' is not available here (torch finds no CUDA device); "
                         "use --device cpu or auto")
    if device == "auto":
        device = "cuda" if torch.cuda.is_available() else "cpu"
    return torch.device(device)


def torch_threads() -> int:
    """Threads to run torch on: one in a worker of a parallel stage
    (:func:`onionsort.stages.parallel.torch_threads`), else :data:`TORCH_THREADS`. A process
    that never loaded the executor (a robot's own) is no such worker."""
    parallel = sys.modules.get("onionsort.stages.parallel")
    return TORCH_THREADS if parallel is None else parallel.torch_threads()


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()[:16]


@dataclass
class PerceptionModels:
    """The trained detector, state classifier and inspection classifier, loaded from one
    folder, with a hash of each file as it was loaded."""

    classifier: object
    detector: object
    folder: Path
    hashes: dict[str, str] | None = None
    inspection: object = None
    device: str = "cpu"
    robot_inspection: object = None
    #: The detector that finds the onion in the Sawyer's views, where the folder has one
    #: (:data:`ROBOT_DETECTOR_FILE`); else :attr:`detector` finds it there too.
    robot_detector: object = None
    #: Per difficulty level, the robot's fused calibration fitted on that level's own onions
    #: (the file's ``levels``); :meth:`at_level` applies one.
    robot_fusion_levels: dict = field(default_factory=dict)

    @classmethod
    def load_cached(cls, folder: Path | str | None = None, device: str = "auto"
                    ) -> PerceptionModels:
        """:meth:`load`, once per process for each folder and device: a worker of a parallel
        stage loads the models once for all the pieces it runs."""
        where = DEFAULT_MODELS if folder is None else Path(folder)
        files = tuple((name, (where / name).stat().st_mtime_ns)
                      for name in (*_FILES.values(), *_ROBOT_FILES.values(), ROBOT_FUSION_FILE)
                      if (where / name).is_file())  # a model trained again is loaded again
        key = (where.resolve(), device, files)
        if key not in _LOADED:
            _LOADED[key] = cls.load(folder, device)
        return _LOADED[key]

    @classmethod
    def load(cls, folder: Path | str | None = None, device: str = "auto") -> PerceptionModels:
        """Load ``state_classifier.pt``, ``detector.pt`` and ``inspection_classifier.pt``
        from ``folder`` (default: shipped) onto ``device`` (``auto``, ``cpu`` or ``cuda``;
        :func:`resolve_device`), and ``robot_inspection_classifier.pt`` and
        ``robot_detector.pt`` where the folder has them (the Sawyer's inspection reads them
        instead of the shared ones), with the calibration of its fused probability from
        :data:`ROBOT_FUSION_FILE` where the folder has that too.

        Raises
        ------
        FileNotFoundError
            Naming the missing file and the command that trains it.
        ValueError
            If ``device`` is unknown or not available.
        """
        import torch

        from perception import Detector
        from perception.inspection import InspectionClassifier
        from state_abstraction.classifier import StateClassifier

        where = resolve_device(device)
        torch.set_num_threads(torch_threads())
        folder = cls.check_folder(folder)
        robot = folder / ROBOT_INSPECTION_FILE
        robot_inspection = (InspectionClassifier.load(robot, device=where) if robot.is_file()
                            else None)
        robot = folder / ROBOT_DETECTOR_FILE
        robot_detector = Detector.load(robot, device=where) if robot.is_file() else None
        levels = {}
        if robot_inspection is not None and (folder / ROBOT_FUSION_FILE).is_file():
            pooled, levels = _read_fusion_file(folder / ROBOT_FUSION_FILE)
            for rule, calibration in pooled.items():
                robot_inspection.set_fused_calibration(rule, calibration)
        return cls(classifier=StateClassifier.load(folder / CLASSIFIER_FILE, device=where),
                   detector=Detector.load(folder / DETECTOR_FILE, device=where), folder=folder,
                   hashes=_hashes(folder),
                   inspection=InspectionClassifier.load(folder / INSPECTION_FILE,
                                                        device=where),
                   device=str(where),
                   robot_inspection=robot_inspection, robot_fusion_levels=levels,
                   robot_detector=robot_detector)

    def at_level(self, level) -> PerceptionModels:
        """These models on a line of difficulty ``level`` (a level's name or a
        :class:`robot.difficulty.Difficulty`): the Sawyer's fused P(blemished) calibrated by
        that level's own calibration where :data:`ROBOT_FUSION_FILE` holds one, else these
        models as loaded (the calibration pooled over every level). Only how sure the fused
        probability is changes; the networks are shared, not copied."""
        own = self.robot_fusion_levels.get(_level_name(level))
        if own is None or self.robot_inspection is None:
            return self
        robot = copy.copy(self.robot_inspection)
        robot.fused_calibration = {**self.robot_inspection.fused_calibration, **own}
        return dataclasses.replace(self, robot_inspection=robot)

    def fused_calibration_of(self, level) -> str:
        """Which calibration :meth:`at_level` applies on ``level``: the level's name, or
        ``"pooled"``."""
        name = _level_name(level)
        return name if name in self.robot_fusion_levels else "pooled"

    @staticmethod
    def check_folder(folder: Path | str | None = None) -> Path:
        """The models folder (``folder``, or the shipped one), once it holds the files
        :meth:`load` needs.

        Raises
        ------
        FileNotFoundError
            Naming the missing file and the command that trains it.
        """
        folder = DEFAULT_MODELS if folder is None else Path(folder)
        for name, command in ((CLASSIFIER_FILE, "onionsort train state-classifier"),
                              (DETECTOR_FILE, "onionsort train detector"),
                              (INSPECTION_FILE, "onionsort train inspection")):
            if not (folder / name).is_file():
                raise FileNotFoundError(f"{folder} has no {name}; train it with `{command} "
                                        f"--data DATASET --out {folder}`")
        return folder

    @classmethod
    def frames_per_step_of(cls, folder: Path | str | None = None) -> int | None:
        """The frames of a step that the state classifier of ``folder`` reads, from its
        checkpoint's configuration, without loading torch (a parallel stage checks its input
        with it before its workers load the models); None where any model's checkpoint cannot
        be read so (:meth:`load` then says what is wrong with it). A missing file raises as in
        :meth:`check_folder`."""
        folder = cls.check_folder(folder)
        try:  # every model's, so that a file that is no checkpoint is found here too
            configs = {name: checkpoint_config(folder / name)
                       for name in (*_FILES.values(), *_ROBOT_FILES.values())
                       if (folder / name).is_file()}
            frames = configs[CLASSIFIER_FILE]["frames"]
        except Exception:  # any unreadable file: loading it names the fault
            return None
        return frames if isinstance(frames, int) and not isinstance(frames, bool) \
            and frames >= 1 else None

    @classmethod
    def frames_per_step_for_workers(cls, folder: Path | str | None = None,
                                    device: str = "auto") -> int:
        """The frames of a step that the state classifier of ``folder`` reads, checked in this
        process for a stage whose workers load the models: from the checkpoints without torch
        (:meth:`frames_per_step_of`) where they read so, else by loading them here, which names
        what is wrong. ``device="cuda"`` is checked now, where there is none."""
        if device == "cuda":
            resolve_device(device)
        frames = cls.frames_per_step_of(folder)
        return frames if frames is not None else cls.load_cached(folder,
                                                                 device).frames_per_step

    @property
    def frames_per_step(self) -> int:
        """Frames of a step that the state classifier reads."""
        return int(self.classifier.config.frames)

    def describe(self) -> dict:
        """Which models these are: their folder (``shipped`` for the package's own) and a hash
        of each file as loaded (for the records they write)."""
        return self.describe_folder(self.folder, self.hashes)

    @staticmethod
    def describe_folder(folder: Path | str | None = None,
                        hashes: dict[str, str] | None = None) -> dict:
        """:meth:`describe` of the models in ``folder`` (default: shipped), from their files,
        without loading them (``hashes``: the files' as they were loaded)."""
        folder = DEFAULT_MODELS if folder is None else Path(folder)
        shipped = folder.resolve() == DEFAULT_MODELS.resolve()
        return {"folder": "shipped" if shipped else str(folder),
                **(hashes or _hashes(folder))}

    def inspection_for(self, camera: str):
        """The inspection classifier that reads ``camera``'s views: ``"sorter"`` the shared
        one; ``"robot"`` the Sawyer's own where one was loaded, else the shared one."""
        return _of_camera(camera, self.robot_inspection, self.inspection)

    def detector_for(self, camera: str):
        """The detector that finds the onion in ``camera``'s views: ``"sorter"`` the shared
        one; ``"robot"`` the Sawyer's own where one was loaded, else the shared one."""
        return _of_camera(camera, self.robot_detector, self.detector)

    def inspector(self, *, rule: str | None = None, threshold: float | None = None,
                  camera: str = "sorter"):
        """The inspection (:class:`perception.inspection.Inspector`) of ``camera``'s views
        (:meth:`inspection_for`): the detector finds the onion (:meth:`detector_for`), the
        inspection classifier reads it, views are fused by ``rule`` (the classifier's own by
        default) and an onion called blemished from ``threshold`` (the task's cost threshold by
        default, :func:`~onionsort.configs.common.sorting_threshold`)."""
        from irl.domains.onion_sorting import SORTING_TASK
        from perception.inspection import Inspector

        classifier = self.inspection_for(camera)
        values = tuple(SORTING_TASK.value_index("prediction", v)
                       for v in ("good", "bad", "unknown"))
        return Inspector(self.detector_for(camera), classifier,
                         rule=classifier.rule if rule is None else rule,
                         threshold=sorting_threshold() if threshold is None else threshold,
                         values=values)

    def perceive(self, steps, first_step: int = 0):
        """:func:`state_abstraction.perceive.perceive_steps` with these models."""
        from state_abstraction.perceive import perceive_steps

        return perceive_steps(self.classifier, steps, self.inspector(), first_step=first_step)


def _of_camera(camera: str, robot, shared):
    """The model that reads ``camera``'s views: ``robot`` for the Sawyer's (``"robot"``) where
    there is one, else ``shared``."""
    if camera not in ("sorter", "robot"):
        raise ValueError(f"camera must be 'sorter' or 'robot'; got {camera!r}")
    return robot if camera == "robot" and robot is not None else shared


def _hashes(folder: Path) -> dict[str, str]:
    """A hash of each model file in ``folder`` (the Sawyer's own models only where the folder
    has them)."""
    out = {key: _digest(folder / name) for key, name in _FILES.items()}
    for key, name in _ROBOT_FILES.items():
        if (folder / name).is_file():
            out[key] = _digest(folder / name)
    return out


def read_fused_calibration(path: Path | str) -> dict[str, tuple]:
    """The map ``(low, high, form)`` of each fusion rule in a :data:`ROBOT_FUSION_FILE`
    (:func:`perception.fusion.check_calibration`; ``"slopes"`` where the file names no form;
    under ``"powers"`` the entry's ``low_power`` and ``high_power`` after the form): the
    calibration pooled over every level it was fitted on.

    Raises
    ------
    ValueError
        Naming the file, if it is not such a file or a calibration in it is not monotone.
    """
    return _read_fusion_file(path)[0]


def _read_fusion_file(path: Path | str) -> tuple[dict, dict[str, dict]]:
    """``(pooled, levels)`` of a :data:`ROBOT_FUSION_FILE`, read once: the pooled maps per
    fusion rule (:func:`read_fused_calibration`) and, per difficulty level, the maps fitted on
    that level's own onions (``{}`` where it was not fitted by level).

    Raises
    ------
    ValueError
        Naming the file (and the level), if it or an entry of it is not such a calibration.
    """
    import json

    path = Path(path)
    try:
        doc = json.loads(path.read_text())
        rules, levels = doc["rules"], doc.get("levels", {})
        if not isinstance(levels, dict):
            raise TypeError(f"'levels' is a {type(levels).__name__}, not a mapping")
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        raise ValueError(f"{path} is not a fused-probability calibration ({exc})") from None
    return (_rules(path, rules, ""),
            {str(level): _rules(path, entry, f"level {level!r}")
             for level, entry in levels.items()})


def _rules(path: Path, rules, where: str) -> dict[str, tuple]:
    """The checked calibrations of one ``rules`` entry of the file ``path`` (``where``: which
    entry, for the error)."""
    from perception.fusion import FUSION_RULES, check_calibration

    at = f" ({where})" if where else ""
    try:
        out = {rule: check_calibration((value["low"], value["high"], value.get("form", "slopes"),
                                        *(value[k] for k in ("low_power", "high_power")
                                          if k in value)))
               for rule, value in rules.items()}
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        raise ValueError(f"{path} is not a fused-probability calibration{at} ({exc})"
                         ) from None
    unknown = sorted(set(out) - set(FUSION_RULES))
    if unknown:
        raise ValueError(f"{path} names unknown fusion rules {unknown}{at}; the rules are "
                         f"{FUSION_RULES}")
    return out


def _level_name(level) -> str | None:
    """A difficulty level's name, from its name or a :class:`robot.difficulty.Difficulty`."""
    return getattr(level, "name", level)


def model_mismatch(a: dict | None, b: dict | None) -> list[str]:
    """The model hashes on which two :meth:`PerceptionModels.describe` records differ."""
    a, b = a or {}, b or {}
    return [k for k in HASH_KEYS if a.get(k) != b.get(k)]

