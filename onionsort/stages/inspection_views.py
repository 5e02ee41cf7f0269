"""The inspection views of a dataset, one row per view that shows an onion, with the crop the
inspection classifier reads (:func:`inspection_views`).

The sorter's views (``source: human``) and the Sawyer's (``source: robot``) are read alike;
where a crop is cut round a detector's box, the Sawyer's views may have a detector of their own
(``robot_detector``, :meth:`onionsort.perception_models.PerceptionModels.detector_for`).

Example::

    from onionsort.stages.inspection_views import inspection_views
    views = inspection_views("runs/data", "test")        # crops of the labelled boxes
    print(len(views), views.source[:3], views.labels[:3])
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

__all__ = ["MIN_CROP_PIXELS", "InspectionViews", "inspection_views"]

MIN_CROP_PIXELS = 300
"""A view is read only if the onion shows at least this many pixels (a rim at the edge of the
sorter's view is no inspection)."""


@dataclass
class InspectionViews:
    """The inspection views of a dataset split that show an onion, one row each.

    ``crops`` (N, S, S, 3) uint8 (context crops of the true box, or the crops inference cuts
    round the detector's box); ``labels`` (N,) rot in view (1, 0, -1 unclear;
    :func:`perception.inspection.rot_label`); ``classes`` (N,) the onion's class; ``level``,
    ``source`` (N,) str; ``onion`` (N,) a key naming the onion (the views of one onion in one
    session or line-up share it); ``view`` (N,) the robot's view index (-1 for the sorter's);
    ``found`` (N,) bool, whether the detector found the onion (always True for crops of the
    labelled box).
    """

    crops: np.ndarray
    labels: np.ndarray
    classes: np.ndarray
    level: np.ndarray
    source: np.ndarray
    onion: np.ndarray
    view: np.ndarray
    found: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))

    def __len__(self) -> int:
        return len(self.labels)

    def subset(self, mask: np.ndarray) -> InspectionViews:
        return InspectionViews(**{f.name: getattr(self, f.name)[mask] for f in fields(self)})

    @classmethod
    def concat(cls, parts: list[InspectionViews]) -> InspectionViews:
        """The rows of several sets, in order (onion keys prefixed by the set's index, so
        that onions of two datasets never share one)."""
        out = {f.name: np.concatenate([getattr(p, f.name) for p in parts])
               for f in fields(cls)}
        out["onion"] = np.concatenate([np.char.add(f"{i}:", p.onion.astype(str))
                                       for i, p in enumerate(parts)])
        return cls(**out)

    def weights(self, level_weights: dict[str, float] | None = None) -> np.ndarray:
        """Each (level, source, label) cell weighs the same in all, times its level's weight
        (:data:`level_weights`, 1 where not given)."""
        level_weights = level_weights or {}
        out = np.zeros(len(self))
        cells = defaultdict(list)
        for i, key in enumerate(zip(self.level, self.source, self.labels, strict=True)):
            cells[key].append(i)
        for (level, _, _), rows in cells.items():
            out[rows] = float(level_weights.get(str(level), 1.0)) / len(rows)
        return out * len(self) / out.sum()


def _held_onion(record: dict) -> int | None:
    """Index of the onion an inspection record is about: the one showing most pixels, if it
    shows at least :data:`MIN_CROP_PIXELS`."""
    pixels = record.get("visible_pixels")
    boxes = record["boxes"]
    if not boxes:
        return None
    if pixels is None:  # a dataset written before the field: the largest box
        pixels = [(b[2] - b[0]) * (b[3] - b[1]) for b in boxes]
    k = int(np.argmax(pixels))
    return k if pixels[k] >= MIN_CROP_PIXELS else None


def inspection_views(root: Path | str, split: str, *, detector=None,
                     dataset_level: str | None = None, allow_empty: bool = False,
                     image_map=None, context: bool = False, robot_detector=None,
                     batch_size: int = 32) -> InspectionViews:
    """The inspection views of ``split`` (or ``"all"``) of dataset ``root`` that show an onion.

    Without ``detector``: context crops of the true boxes (for training,
    :func:`perception.train_inspection.context_crop`). With it: the crops inference cuts round
    the detector's best box (:meth:`perception.inspection.Inspector.boxes`), ``found`` False
    (and a blank crop) where it finds none; with ``context`` too, context crops round that
    box (for training on the framing the detector gives). ``dataset_level`` names the level
    of records that do not name theirs (datasets written before the field). A split with no
    such view is an error, or empty with ``allow_empty``. ``image_map`` changes each view as it
    is read (:data:`recordings.labels.dataset.ImageMap`). ``robot_detector``, where given with
    ``detector``, finds the onion in the Sawyer's views instead (the rows keep their order);
    each detector reads ``batch_size`` views at a time.

    Raises
    ------
    ValueError
        If ``robot_detector`` is given without ``detector``, or (unless ``allow_empty``) the
        split shows no onion.
    """
    from perception.inspection import CROP_SIZE, best_box, crop_onion, rot_label
    from perception.train_inspection import CONTEXT_SIZE, context_crop
    from recordings.labels.dataset import read_metadata, read_split, split_names

    if detector is None and robot_detector is not None:
        raise ValueError("a robot_detector needs a detector for the sorter's views too")
    meta = read_metadata(root)
    if "inspection" not in meta.get("views", ["camera"]):
        raise ValueError(f"{root} holds no inspection views; render a dataset with them "
                         "(`onionsort dataset`)")
    levels = meta.get("session_difficulty")
    default_level = dataset_level or _dataset_level(meta)
    size = CONTEXT_SIZE if detector is None or context else CROP_SIZE
    rows = defaultdict(list)
    finders = {"robot": detector if robot_detector is None else robot_detector,
               "human": detector}
    pending = {source: [] for source in finders}  # (row, image) waiting for a detector

    def flush(source: str) -> None:
        batch = pending[source]
        if not batch:
            return
        found = finders[source].detect([image for _, image in batch])
        for (row, image), det in zip(batch, found, strict=True):
            box = best_box(det)
            rows["found"][row] = box is not None
            rows["crops"][row] = (np.zeros((size, size, 3), np.uint8) if box is None
                                  else context_crop(image, box) if context
                                  else crop_onion(image, box))
        batch.clear()

    for name in split_names(split):
        for frame in read_split(root, name, view="inspection", image_map=image_map):
            rec = frame.record
            k = _held_onion(rec)
            if k is None:
                continue
            source = rec.get("source", "human")
            level = rec.get("difficulty") or (
                levels[rec["session"]] if levels and source == "human" and "session" in rec
                else default_level)
            rot = rec.get("rot_pixels")
            visible = (rec.get("visible_pixels") or [0] * len(rec["boxes"]))[k]
            blemished = bool(rec["classes"][k])
            rows["labels"].append(rot_label(None if rot is None else rot[k], visible, blemished))
            rows["classes"].append(int(blemished))
            rows["level"].append(level)
            rows["source"].append(source)
            if source == "robot":
                rows["onion"].append(f"{name}/lineup{rec['lineup']}/{rec['index']}")
                rows["view"].append(int(rec.get("view", 0)))
            elif rec.get("onions"):
                rows["onion"].append(f"{name}/session{rec['session']}/{rec['onions'][k]}")
                rows["view"].append(-1)
            else:  # an imported view names no onion: an onion of its own
                rows["onion"].append(f"{name}/{rec.get('image', rec['color'])}")
                rows["view"].append(-1)
            if detector is None:
                rows["crops"].append(context_crop(frame.color, rec["boxes"][k]))
                rows["found"].append(True)
            else:  # filled in when its detector reads the batch
                finder = "robot" if source == "robot" else "human"
                pending[finder].append((len(rows["crops"]), frame.color))
                rows["crops"].append(None)
                rows["found"].append(False)
                if len(pending[finder]) == batch_size:
                    flush(finder)
    for finder in pending:  # what is left of each batch (none without a detector)
        flush(finder)
    if not rows["labels"] and not allow_empty:
        raise ValueError(f"split {split!r} of {root} holds no inspection view that shows an "
                         f"onion of {MIN_CROP_PIXELS} pixels or more")
    return InspectionViews(
        crops=np.asarray(rows["crops"], np.uint8).reshape(-1, size, size, 3),
        **{k: np.asarray(rows[k]) for k in ("labels", "classes", "level", "source", "onion",
                                             "view", "found")})


def _dataset_level(meta: dict) -> str:
    config = meta.get("config", {})
    difficulty = config.get("difficulty", "clean")
    if isinstance(difficulty, dict):
        return difficulty.get("name", "custom")
    return "mix" if isinstance(difficulty, list) else str(difficulty)
