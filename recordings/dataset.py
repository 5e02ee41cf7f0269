"""Labelled-frame datasets on disk, for training and calibrating perception.

Layout of a dataset folder ``DIR``::

    DIR/dataset.json                 format, seed, configuration, classes, factors, splits
    DIR/<split>/color/NNNNNN.png     RGB frames (stored as PNG, BGR on disk as OpenCV writes)
    DIR/<split>/depth/NNNNNN.png     16-bit depth in millimetres
    DIR/<split>/labels.json          one record per frame (below)

with splits ``train``, ``val`` and ``test`` made of whole sessions (frames of one session are
correlated, so a split never shares a session with another). A frame record holds ``color``,
``depth`` (paths relative to the split folder), ``boxes`` (``[x_min, y_min, x_max, y_max]`` in
pixels, exclusive max, of the visible onions), ``classes`` (0 good, 1 blemished), the true
``state`` and its factors ``onion``, ``end_effector``, ``prediction`` (encodings of
``irl.domains.onion_sorting``), ``action``, ``occluded`` (the passer-by crossed during the step),
``occluded_fraction``, ``phase`` (0 = the state at rest), ``session`` and ``frame``.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from irl.domains.onion_sorting import decode_state
from robot.labels import Frame

__all__ = ["CLASSES", "SPLITS", "DatasetWriter", "LabelledFrame", "read_split"]

FORMAT = "onionsort.dataset/1"
CLASSES = ("good", "blemished")
SPLITS = ("train", "val", "test")


def frame_record(frame: Frame, session: int, name: str) -> dict:
    """The JSON record of one frame (see the module docstring)."""
    boxes, classes = [], []
    for onion in frame.onions:
        if onion.box is not None and onion.visible_pixels > 0:
            boxes.append([int(v) for v in onion.box])
            classes.append(int(onion.blemished))
    state = decode_state(frame.step.state)
    return {
        "color": f"color/{name}.png",
        "depth": f"depth/{name}.png",
        "boxes": boxes,
        "classes": classes,
        "state": int(frame.step.state),
        "onion": int(state.onion),
        "end_effector": int(state.end_effector),
        "prediction": int(state.prediction),
        "action": int(frame.step.action),
        "occluded": bool(frame.step.occluded),
        "occluded_fraction": float(frame.occluded_fraction),
        "phase": int(frame.phase),
        "session": int(session),
        "frame": int(frame.index),
    }


class DatasetWriter:
    """Writes frames into a new dataset folder; refuses to overwrite an existing one.

    ``labels.json`` of each split is rewritten (atomically) as frames arrive, so an interrupted
    run leaves a readable dataset of the frames written so far.
    """

    def __init__(self, root: Path | str, metadata: dict) -> None:
        self.root = Path(root)
        if (self.root / "dataset.json").exists():
            raise FileExistsError(f"{self.root} already holds a dataset; choose a new --out")
        self.metadata = {"format": FORMAT, "classes": list(CLASSES), **metadata}
        self._records: dict[str, list[dict]] = {s: [] for s in SPLITS}
        for split in SPLITS:
            (self.root / split / "color").mkdir(parents=True, exist_ok=True)
            (self.root / split / "depth").mkdir(parents=True, exist_ok=True)

    def add(self, split: str, frame: Frame, session: int) -> None:
        if split not in SPLITS:
            raise ValueError(f"split must be one of {SPLITS}; got {split!r}")
        records = self._records[split]
        name = f"{len(records):06d}"
        folder = self.root / split
        cv2.imwrite(str(folder / "color" / f"{name}.png"),
                    cv2.cvtColor(np.ascontiguousarray(frame.color), cv2.COLOR_RGB2BGR))
        depth_mm = np.clip(np.nan_to_num(frame.depth) * 1000.0, 0, 65535).astype(np.uint16)
        cv2.imwrite(str(folder / "depth" / f"{name}.png"), depth_mm)
        records.append(frame_record(frame, session, name))

    def flush(self, split: str | None = None) -> None:
        for s in SPLITS if split is None else (split,):
            _write_json(self.root / s / "labels.json", self._records[s])

    def close(self) -> None:
        self.flush()
        counts = {s: len(r) for s, r in self._records.items()}
        _write_json(self.root / "dataset.json", {**self.metadata, "splits": counts})


def _write_json(path: Path, doc) -> None:
    tmp = path.with_name(path.name + ".partial")
    tmp.write_text(json.dumps(doc))
    tmp.replace(path)


@dataclass(frozen=True)
class LabelledFrame:
    """One frame of a dataset split, loaded: ``color`` (H, W, 3) uint8 RGB, ``depth`` (H, W)
    float32 metres, and its record (see the module docstring)."""

    color: np.ndarray
    depth: np.ndarray
    record: dict


def read_split(root: Path | str, split: str) -> Iterator[LabelledFrame]:
    """Iterate the frames of one split of a dataset folder."""
    root = Path(root)
    meta_path = root / "dataset.json"
    if not meta_path.exists():
        raise FileNotFoundError(f"{root} is not a dataset folder (no dataset.json)")
    meta = json.loads(meta_path.read_text())
    if meta.get("format") != FORMAT:
        raise ValueError(f"{meta_path}: format must be {FORMAT!r}; got {meta.get('format')!r}")
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}; got {split!r}")
    records: Iterable[dict] = json.loads((root / split / "labels.json").read_text())
    for rec in records:
        color = cv2.imread(str(root / split / rec["color"]), cv2.IMREAD_COLOR)
        depth = cv2.imread(str(root / split / rec["depth"]), cv2.IMREAD_UNCHANGED)
        if color is None or depth is None:
            raise ValueError(f"{root / split}: frame {rec['color']} is missing or unreadable")
        yield LabelledFrame(color=cv2.cvtColor(color, cv2.COLOR_BGR2RGB),
                            depth=depth.astype(np.float32) / 1000.0, record=rec)
