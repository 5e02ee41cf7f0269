"""The perception models a stage runs: the detector and the state classifier, from one folder.

The default models ship with the package (``onionsort/models/``); ``onionsort train`` and
``onionsort calibrate`` reproduce them (see the README). Every output that perception produces
records :meth:`PerceptionModels.describe` (a hash of each model), so a calibration and the
sessions it is used with can be checked to come from the same models.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

__all__ = ["CALIBRATION_FILE", "DEFAULT_MODELS", "PerceptionModels", "model_mismatch"]

DEFAULT_MODELS = Path(__file__).resolve().parent.parent / "models"
CLASSIFIER_FILE = "state_classifier.pt"
DETECTOR_FILE = "detector.pt"
CALIBRATION_FILE = "calibration.json"
#: The keys of :meth:`PerceptionModels.describe` that identify the models.
HASH_KEYS = ("state_classifier_sha256", "detector_sha256")


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()[:16]


@dataclass
class PerceptionModels:
    """The trained detector and state classifier, loaded from one folder, with a hash of each
    file as it was loaded."""

    classifier: object
    detector: object
    folder: Path
    hashes: dict[str, str] | None = None

    @classmethod
    def load(cls, folder: Path | str | None = None) -> PerceptionModels:
        """Load ``state_classifier.pt`` and ``detector.pt`` from ``folder`` (default: shipped).

        Raises
        ------
        FileNotFoundError
            Naming the missing file and the command that trains it.
        """
        import torch

        from perception import Detector
        from state_abstraction.classifier import StateClassifier

        torch.set_num_threads(2)
        folder = DEFAULT_MODELS if folder is None else Path(folder)
        for name, command in ((CLASSIFIER_FILE, "onionsort train state-classifier"),
                              (DETECTOR_FILE, "onionsort train detector")):
            if not (folder / name).is_file():
                raise FileNotFoundError(f"{folder} has no {name}; train it with `{command} "
                                        f"--data DATASET --out {folder}`")
        return cls(classifier=StateClassifier.load(folder / CLASSIFIER_FILE),
                   detector=Detector.load(folder / DETECTOR_FILE), folder=folder,
                   hashes={"state_classifier_sha256": _digest(folder / CLASSIFIER_FILE),
                           "detector_sha256": _digest(folder / DETECTOR_FILE)})

    @property
    def frames_per_step(self) -> int:
        """Frames of a step that the state classifier reads."""
        return int(self.classifier.config.frames)

    def describe(self) -> dict:
        """Which models these are: their folder (``shipped`` for the package's own) and a hash
        of each file as loaded (for the records they write)."""
        hashes = self.hashes or {"state_classifier_sha256": _digest(self.folder / CLASSIFIER_FILE),
                                 "detector_sha256": _digest(self.folder / DETECTOR_FILE)}
        shipped = self.folder.resolve() == DEFAULT_MODELS.resolve()
        return {"folder": "shipped" if shipped else str(self.folder), **hashes}

    def perceive(self, steps, first_step: int = 0):
        """:func:`state_abstraction.perceive.perceive_steps` with these models."""
        from state_abstraction.perceive import perceive_steps

        return perceive_steps(self.classifier, steps, self.detector.detect,
                              first_step=first_step)


def model_mismatch(a: dict | None, b: dict | None) -> list[str]:
    """The model hashes on which two :meth:`PerceptionModels.describe` records differ."""
    a, b = a or {}, b or {}
    return [k for k in HASH_KEYS if a.get(k) != b.get(k)]
