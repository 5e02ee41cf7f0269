"""The perception pipeline of the application: models -> perceived steps -> calibration, MCAP.

This is where the detector (:mod:`perception`) and the state classifier
(:mod:`state_abstraction`) meet the recordings: perceiving a labelled dataset to calibrate the
observation model and to measure perception, and perceiving recorded sessions so the learners
can use them.

The default models ship with the package (``onionsort/models/``); ``onionsort train`` and
``onionsort calibrate`` reproduce them (see the README).
"""

from __future__ import annotations

import logging
from collections import defaultdict
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = [
    "DEFAULT_MODELS",
    "PerceptionModels",
    "dataset_sessions",
    "detector_map",
    "evaluate_dataset",
    "perceive_session",
]

logger = logging.getLogger(__name__)

DEFAULT_MODELS = Path(__file__).resolve().parent / "models"
CLASSIFIER_FILE = "state_classifier.pt"
DETECTOR_FILE = "detector.pt"
CALIBRATION_FILE = "calibration.json"


@dataclass
class PerceptionModels:
    """The trained detector and state classifier, loaded from one folder."""

    classifier: object
    detector: object
    folder: Path

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
                   detector=Detector.load(folder / DETECTOR_FILE), folder=folder)

    def describe(self) -> dict:
        """Which models these are (for the records they write)."""
        import hashlib

        def digest(name: str) -> str:
            return hashlib.sha256((self.folder / name).read_bytes()).hexdigest()[:16]

        return {"folder": str(self.folder), "state_classifier_sha256": digest(CLASSIFIER_FILE),
                "detector_sha256": digest(DETECTOR_FILE)}

    def perceive(self, steps, first_step: int = 0):
        """:func:`state_abstraction.perceive.perceive_steps` with these models."""
        from state_abstraction.perceive import perceive_steps

        return perceive_steps(self.classifier, steps, self.detector.detect,
                              first_step=first_step)


# -- labelled datasets --------------------------------------------------------------------------
@dataclass
class DatasetStep:
    """One complete step of a dataset session: its frames, inspection view and labels."""

    colors: list[np.ndarray]
    depths: list[np.ndarray]
    inspection: np.ndarray | None
    record: dict


def _splits(split: str) -> tuple[str, ...]:
    from recordings.dataset import SPLITS

    if split == "all":
        return SPLITS
    if split not in SPLITS:
        raise ValueError(f"split must be one of {(*SPLITS, 'all')}; got {split!r}")
    return (split,)


def dataset_sessions(root: Path | str, split: str, frames_per_step: int
                     ) -> Iterator[list[DatasetStep]]:
    """The complete steps of each session of a dataset split (or of ``"all"``), in order."""
    for name in _splits(split):
        yield from _split_sessions(root, name, frames_per_step)


def _split_sessions(root: Path | str, split: str, frames_per_step: int
                    ) -> Iterator[list[DatasetStep]]:
    from recordings.dataset import read_split

    views = {(f.record["session"], f.record["frame"]): f.color
             for f in read_split(root, split, view="inspection")
             if f.record.get("source", "human") == "human"}
    sessions: dict[int, dict[int, list]] = defaultdict(lambda: defaultdict(list))
    for frame in read_split(root, split):
        rec = frame.record
        sessions[rec["session"]][rec["step"]].append(frame)
    for session in sorted(sessions):
        steps = []
        for step in sorted(sessions[session]):
            frames = sorted(sessions[session][step], key=lambda f: f.record["phase"])
            if len(frames) != frames_per_step:
                break  # the session was cut short by the dataset's frame count
            first = frames[0].record
            steps.append(DatasetStep([f.color for f in frames], [f.depth for f in frames],
                                     views.get((session, first["frame"])), first))
        if steps:
            yield steps


def evaluate_dataset(models: PerceptionModels, root: Path | str, split: str = "test"):
    """Perceive every step of a dataset split and compare with the truth.

    Returns
    -------
    calibration : state_abstraction.calibration.Calibration
        Confusion of each factor on the steps the classifier called unoccluded (exactly the
        steps that become observations).
    metrics : dict
        ``accuracy`` per factor on truly unoccluded steps, ``occlusion_recall``,
        ``occlusion_precision``, ``n_steps``.
    """
    from state_abstraction.calibration import FACTORS, calibrate

    true = {k: [] for k in FACTORS}
    pred = {k: [] for k in FACTORS}
    truly_occluded, called_occluded = [], []
    for steps in dataset_sessions(root, split, models.classifier.config.frames):
        perceived = models.perceive([(s.colors, s.depths, s.inspection) for s in steps])
        for step, seen in zip(steps, perceived, strict=True):
            truly_occluded.append(bool(step.record["occluded"]))
            called_occluded.append(seen.occluded)
            for k in FACTORS:
                true[k].append(int(step.record[k]))
                pred[k].append(int(getattr(seen, k)))
    if not true["onion"]:
        raise ValueError(f"split {split!r} of {root} holds no complete step")
    occ, called = np.array(truly_occluded), np.array(called_occluded)
    observed = ~called
    calibration = calibrate({k: np.array(v)[observed] for k, v in true.items()},
                            {k: np.array(v)[observed] for k, v in pred.items()})
    visible = ~occ
    metrics = {
        "accuracy": {k: float(np.mean(np.array(true[k])[visible] == np.array(pred[k])[visible]))
                     for k in FACTORS},
        "occlusion_recall": float(called[occ].mean()) if occ.any() else 1.0,
        "occlusion_precision": float(occ[called].mean()) if called.any() else 1.0,
        "n_steps": len(occ),
        "n_occluded": int(occ.sum()),
    }
    return calibration, metrics


def detector_map(models: PerceptionModels, root: Path | str, split: str = "test",
                 batch_size: int = 32) -> dict[str, dict[str, float]]:
    """mAP of the detector on a dataset split: ``{"all" | "camera" | "inspection": {...}}``."""
    import json

    from perception.metrics import mean_average_precision
    from perception.train import EVAL_SCORE_THRESHOLD
    from recordings.dataset import read_split

    views = json.loads((Path(root) / "dataset.json").read_text()).get("views", ["camera"])
    gts: dict[str, list] = {}
    dts: dict[str, list] = {}
    for view in views:
        frames = [f for name in _splits(split) for f in read_split(root, name, view=view)]
        gts[view] = [(np.asarray(f.record["boxes"], float).reshape(-1, 4),
                      np.asarray(f.record["classes"], int)) for f in frames]
        dts[view] = []
        for i in range(0, len(frames), batch_size):
            for det in models.detector.detect([f.color for f in frames[i:i + batch_size]],
                                              score_threshold=EVAL_SCORE_THRESHOLD):
                dts[view].append((det.boxes, det.scores, det.classes))
    out = {v: mean_average_precision(gts[v], dts[v]) for v in views}
    out["all"] = mean_average_precision([g for v in views for g in gts[v]],
                                        [d for v in views for d in dts[v]])
    return out


# -- recorded sessions --------------------------------------------------------------------------
def perceive_session(models: PerceptionModels, path: Path | str, *, replace: bool = False,
                     batch_size: int = 32):
    """Run both models on a recorded session and add the perception topics to its file.

    Returns the perceived steps (:class:`state_abstraction.perceive.PerceivedStep`).
    """
    from recordings.perception import add_perception
    from recordings.reader import open_session

    session = open_session(path)
    fps = models.classifier.config.frames
    by_step: dict[int, list] = defaultdict(list)
    for frame in session.frames():
        by_step[frame.step].append(frame)
    numbers = [s.step for s in session.steps]
    if numbers != list(range(len(numbers))):
        raise ValueError(f"{path}: steps must be numbered 0..T-1; got {numbers[:5]}...")
    inputs, first_frames = [], []
    for t in numbers:
        frames = sorted(by_step[t], key=lambda f: int(f.state.get("phase", 0)))
        if len(frames) != fps:
            raise ValueError(f"{path}: step {t} has {len(frames)} frames; the state classifier "
                             f"reads steps of {fps} (record with --frames-per-step {fps})")
        inputs.append(([f.color for f in frames], [f.depth for f in frames],
                       frames[0].inspection))
        first_frames.append(frames[0].index)
    perceived = models.perceive(inputs)
    frames = list(session.frames())
    detections = {}
    for i in range(0, len(frames), batch_size):
        chunk = frames[i:i + batch_size]
        for frame, det in zip(chunk, models.detector.detect([f.color for f in chunk]),
                              strict=True):
            detections[frame.index] = _rows(det)
    views = [f for f in frames if f.inspection_png is not None]
    inspection = {f.index: _rows(d)
                  for f, d in zip(views, models.detector.detect([f.inspection for f in views]),
                                  strict=True)} if views else {}
    docs = [{**seen.to_dict(), "frame": first} for seen, first in zip(perceived, first_frames,
                                                                      strict=True)]
    add_perception(path, docs, detections=detections, inspection=inspection,
                   frame_times={f.index: f.time_ns for f in frames}, models=models.describe(),
                   replace=replace)
    return perceived


def _rows(det) -> list[tuple]:
    boxes, classes, scores = (np.asarray(det.boxes), np.asarray(det.classes),
                              np.asarray(det.scores))
    return [(*boxes[i].tolist(), int(classes[i]), float(scores[i])) for i in range(len(scores))]
