"""Labelled-frame datasets on disk, for training and calibrating perception.

Layout of a dataset folder ``DIR``::

    DIR/dataset.json                 format, seed, configuration, classes, task, splits
    DIR/<split>/color/NNNNNN.png     RGB frames (stored as PNG, BGR on disk as OpenCV writes)
    DIR/<split>/depth/NNNNNN.png     16-bit depth in millimetres
    DIR/<split>/labels.json          one record per frame (below)
    DIR/<split>/inspection/NNNNNN.png   the inspection view (RGB), on the first frame of a step
    DIR/<split>/inspection.json      one record per inspection image (same fields, no depth)

with splits ``train``, ``val`` and ``test`` made of whole sessions (frames of one session are
correlated, so a split never shares a session with another). A frame record holds ``color``,
``depth`` (paths relative to the split folder), ``boxes`` (``[x_min, y_min, x_max, y_max]`` in
pixels, exclusive max, of the onions with at least ``MIN_VISIBLE_PIXELS`` visible pixels),
``classes`` (0 good, 1 blemished), the true
``state`` and the value index of each of its factors under the factor's name (the task's
``decode``; for onion sorting ``onion``, ``end_effector``, ``prediction``), ``action``,
``occluded`` (the passer-by crossed during the step), ``occluded_fraction``, ``phase`` (0 = the
state at rest), ``step``, ``session`` and ``frame``. ``dataset.json`` holds the task
(``task.to_dict()``, under ``"task"``; :func:`dataset_task` reads it back, the onion-sorting
task for datasets that predate the field).

``dataset.json`` lists its ``views``: ``camera`` (the main RGB-D camera) and ``inspection`` (the
close view where the sorter, or the robot, looks at the onion in hand; boxes there are in that
view's pixels; one with every frame of a session). Inspection records have a ``source``:
``human`` (from a session, with the step's labels) or ``robot`` (the Sawyer showing an onion of
a line-up to its inspection camera from several sides: ``lineup``, ``index`` of the onion in
it, ``view`` of the robot's views of it). Besides ``boxes`` and ``classes`` they hold, per box,
``visible_pixels``, ``onions`` (the onion's id, human views) and ``rot_pixels`` (how many of its
pixels show rot, not under the hand: the inspection classifier's labels, where the dataset
measured them), and every record names its ``difficulty`` level. The detector trains on both
views, the inspection classifier on the inspection views, the state classifier on the camera
view.

Frames imported from an annotation tool (``onionsort label import``) name their file
(``image``) and may lack depth (no ``depth`` key: the colour-only models read them). A frame
given no state labels is *box-only*: its record holds ``color``, ``boxes``, ``classes``,
``source`` and ``image`` alone, and serves the detector and the inspection classifier, never the
state classifier or calibration (:func:`read_steps` and :func:`split_sessions` leave it out).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from irl.domains.onion_sorting import SORTING_TASK
from irl.domains.task import TaskDescription
from recordings.session.frames import TruthFrame
from recordings.session.schema import check_task, task_of
from recordings.session.steps import group_steps

__all__ = ["CLASSES", "SPLITS", "VIEWS", "DatasetPart", "DatasetStep", "DatasetWriter",
           "ImageMap", "LabelledFrame", "dataset_task", "read_metadata", "read_records",
           "read_rgb_png", "read_split", "read_steps", "split_names", "split_sessions",
           "write_rgb_png"]

FORMAT = "onionsort.dataset/1"
CLASSES = ("good", "blemished")
SPLITS = ("train", "val", "test")
VIEWS = ("camera", "inspection")
_LABELS = {"camera": "labels.json", "inspection": "inspection.json"}
MIN_VISIBLE_PIXELS = 25
"""Onions with fewer visible pixels (slivers behind the hand or the passer-by) get no box."""
_RECORD_KEYS = ("color", "depth", "source", "boxes", "classes", "state", "action", "occluded",
                "occluded_fraction", "phase", "step", "session", "frame", "lineup", "index",
                "image")
"""Keys of a frame record besides the task's factors; a factor may not take one of these."""


def _check_task(task: TaskDescription) -> TaskDescription:
    return check_task(task, _RECORD_KEYS, "a frame record")


def frame_record(frame: TruthFrame, session: int, name: str, view: str = "camera",
                 task: TaskDescription = SORTING_TASK, difficulty: str | None = None) -> dict:
    """The JSON record of one frame in ``view`` (see the module docstring); the state's
    factors are those of ``task``."""
    boxes, classes, rot = [], [], []
    onions = frame.onions if view == "camera" else frame.inspection_onions
    for onion in onions:
        if onion.box is not None and onion.visible_pixels >= MIN_VISIBLE_PIXELS:
            boxes.append([int(v) for v in onion.box])
            classes.append(int(onion.blemished))
            rot.append(getattr(onion, "rot_pixels", None))
            rot[-1] = None if rot[-1] is None else int(rot[-1])
    extra = {} if difficulty is None else {"difficulty": difficulty}
    if view == "inspection":
        extra["visible_pixels"] = [int(o.visible_pixels) for o in onions
                                   if o.box is not None and o.visible_pixels >= MIN_VISIBLE_PIXELS]
        extra["onions"] = [int(o.onion_id) for o in onions
                           if o.box is not None and o.visible_pixels >= MIN_VISIBLE_PIXELS]
        if any(r is not None for r in rot):
            extra["rot_pixels"] = rot
    factors = task.decode(int(frame.step.state))
    images = ({"color": f"color/{name}.png", "depth": f"depth/{name}.png"} if view == "camera"
              else {"color": f"inspection/{name}.png"})
    return {
        **images,
        "source": "human",
        "boxes": boxes,
        "classes": classes,
        "state": int(frame.step.state),
        **factors,
        "action": int(frame.step.action),
        "occluded": bool(frame.step.occluded),
        "occluded_fraction": float(frame.occluded_fraction),
        "phase": int(frame.phase),
        "step": int(frame.step.step),
        "session": int(session),
        "frame": int(frame.index),
        **extra,
    }


class DatasetWriter:
    """Writes frames into a new dataset folder; refuses to overwrite an existing one.

    ``labels.json`` of each split is rewritten (atomically) as frames arrive; ``dataset.json``,
    the mark of a finished dataset, is written by :meth:`close` alone, so an interrupted run
    never leaves a folder that reads as a finished dataset. ``task`` (the onion-sorting task
    by default) names the factors of the records and is stored in ``dataset.json`` under
    ``"task"``.
    """

    def __init__(self, root: Path | str, metadata: dict, *,
                 task: TaskDescription = SORTING_TASK) -> None:
        self.root = Path(root)
        if (self.root / "dataset.json").exists():
            raise FileExistsError(f"{self.root} already holds a dataset; choose a new --out")
        if "task" in metadata:
            raise ValueError("metadata must not hold 'task'; pass the task as task=")
        self.task = _check_task(task)
        self.metadata = {"format": FORMAT, "classes": list(CLASSES), "views": list(VIEWS),
                         **metadata, "task": self.task.to_dict()}
        self._records = {(s, v): [] for s in SPLITS for v in VIEWS}
        for split in SPLITS:
            for sub in ("color", "depth", "inspection"):
                (self.root / split / sub).mkdir(parents=True, exist_ok=True)

    def add(self, split: str, frame: TruthFrame, session: int,
            difficulty: str | None = None) -> None:
        """Add a frame of ``session`` (and its inspection view) to ``split``; ``difficulty``
        names the session's perception difficulty in its records."""
        _check_split(split)
        records, close = self._records[split, "camera"], self._records[split, "inspection"]
        camera, view = _write_frame(self.root / split, frame, session, f"{len(records):06d}",
                                    f"{len(close):06d}", self.task, difficulty)
        records.append(camera)
        if view is not None:
            close.append(view)

    def add_robot_view(self, split: str, rgb: np.ndarray, labels, lineup: int, index: int,
                       view: int = 0, difficulty: str | None = None) -> None:
        """Add an inspection view rendered at the robot's station (Sawyer holding an onion).

        ``labels`` are ``(box, blemished, visible_pixels[, rot_pixels])`` of each onion in it
        (:class:`robot.station_cameras.InspectionLabel`); the record has ``source: "robot"``,
        ``lineup``, ``index`` (the onion's place in the line-up), ``view`` (which of the
        robot's views of it) and ``difficulty``, and no state (the robot's views are for the
        detector and the inspection classifier only).
        """
        _check_split(split)
        records = self._records[split, "inspection"]
        records.append(_write_robot_view(self.root / split, f"{len(records):06d}", rgb, labels,
                                         lineup, index, view, difficulty))

    def add_image(self, split: str, view: str, record: dict, color: np.ndarray, *,
                  depth_mm: np.ndarray | None = None, png: bytes | None = None) -> dict:
        """Add a frame that comes with its record (an imported one) to ``split`` in ``view``.

        ``color`` (H, W, 3) uint8 RGB is written as PNG, or ``png`` (the PNG file of exactly
        those pixels) as it is; ``depth_mm`` (H, W) uint16 millimetres, camera view only.
        ``record`` gets the image paths (``color``, ``depth`` when there is depth) and is
        returned. A record without ``state`` is box-only: the detector and the inspection
        classifier use it, the state classifier and calibration do not (:func:`read_steps`).
        """
        _check_split(split)
        if view not in VIEWS:
            raise ValueError(f"view must be one of {VIEWS}; got {view!r}")
        if depth_mm is not None and view != "camera":
            raise ValueError("only the camera view has depth")
        records = self._records[split, view]
        name = f"{len(records):06d}"
        folder = self.root / split
        sub = "color" if view == "camera" else "inspection"
        if png is not None:
            tmp = folder / sub / f"{name}.png.partial"
            tmp.write_bytes(png)
            tmp.replace(folder / sub / f"{name}.png")
        else:
            write_rgb_png(folder / sub / f"{name}.png", color)
        record = {**record, "color": f"{sub}/{name}.png"}
        record.pop("depth", None)
        if depth_mm is not None:
            _write_png(folder / "depth" / f"{name}.png", np.asarray(depth_mm, np.uint16))
            record["depth"] = f"depth/{name}.png"
        records.append(record)
        return record

    def add_part(self, split: str, part: DatasetPart) -> None:
        """Add the records of a :class:`DatasetPart` of ``split`` (its images are written
        already), after those added so far."""
        _check_split(split)
        if part.split != split:
            raise ValueError(f"the part holds frames of {part.split!r}, not {split!r}")
        for view in VIEWS:
            self._records[split, view].extend(part.records[view])

    def flush(self, split: str | None = None) -> None:
        for s in SPLITS if split is None else (split,):
            for view in VIEWS:
                _write_json(self.root / s / _LABELS[view], self._records[s, view])

    def close(self) -> None:
        self.flush()
        counts = {s: len(self._records[s, "camera"]) for s in SPLITS}
        inspection = {s: len(self._records[s, "inspection"]) for s in SPLITS}
        _write_json(self.root / "dataset.json",
                    {**self.metadata, "splits": counts, "inspection_splits": inspection})


class DatasetPart:
    """The frames of one piece of a dataset (a session, a robot line-up) in one split, written
    under names of their own (``PREFIX_NNNN``), so that pieces rendered at the same time, in
    other processes, never collide; :meth:`DatasetWriter.add_part` then adds their records,
    in the pieces' order, whichever finished first."""

    def __init__(self, root: Path | str, split: str, prefix: str, *,
                 task: TaskDescription = SORTING_TASK) -> None:
        _check_split(split)
        self.folder, self.split, self.prefix = Path(root) / split, split, prefix
        self.task = _check_task(task)
        self.records: dict[str, list[dict]] = {view: [] for view in VIEWS}

    def _name(self, view: str) -> str:
        return f"{self.prefix}_{len(self.records[view]):04d}"

    def add(self, frame: TruthFrame, session: int, difficulty: str | None = None) -> None:
        """As :meth:`DatasetWriter.add`."""
        camera, view = _write_frame(self.folder, frame, session, self._name("camera"),
                                    self._name("inspection"), self.task, difficulty)
        self.records["camera"].append(camera)
        if view is not None:
            self.records["inspection"].append(view)

    def add_robot_view(self, rgb: np.ndarray, labels, lineup: int, index: int, view: int = 0,
                       difficulty: str | None = None) -> None:
        """As :meth:`DatasetWriter.add_robot_view`."""
        self.records["inspection"].append(_write_robot_view(
            self.folder, self._name("inspection"), rgb, labels, lineup, index, view,
            difficulty))


def _check_split(split: str) -> None:
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}; got {split!r}")


def _write_frame(folder: Path, frame: TruthFrame, session: int, name: str, view_name: str,
                 task: TaskDescription, difficulty: str | None) -> tuple[dict, dict | None]:
    """Write a frame's images into a split's ``folder`` as ``name`` (its inspection view as
    ``view_name``); its records (the view's None without one)."""
    write_rgb_png(folder / "color" / f"{name}.png", frame.color)
    depth_mm = np.clip(np.nan_to_num(frame.depth) * 1000.0, 0, 65535).astype(np.uint16)
    _write_png(folder / "depth" / f"{name}.png", depth_mm)
    camera = frame_record(frame, session, name, task=task, difficulty=difficulty)
    if frame.inspection is None:
        return camera, None
    write_rgb_png(folder / "inspection" / f"{view_name}.png", frame.inspection)
    return camera, frame_record(frame, session, view_name, view="inspection", task=task,
                                difficulty=difficulty)


def _write_robot_view(folder: Path, name: str, rgb: np.ndarray, labels, lineup: int,
                      index: int, view: int, difficulty: str | None) -> dict:
    """Write a robot's inspection view into a split's ``folder`` as ``name``; its record."""
    write_rgb_png(folder / "inspection" / f"{name}.png", rgb)
    kept = [tuple(label) for label in labels if label[2] >= MIN_VISIBLE_PIXELS]
    record = {"color": f"inspection/{name}.png", "source": "robot",
              "boxes": [[int(v) for v in k[0]] for k in kept],
              "classes": [int(k[1]) for k in kept],
              "visible_pixels": [int(k[2]) for k in kept],
              "lineup": int(lineup), "index": int(index), "view": int(view)}
    if any(len(k) > 3 and k[3] is not None for k in kept):
        record["rot_pixels"] = [None if len(k) < 4 or k[3] is None else int(k[3])
                                for k in kept]
    if difficulty is not None:
        record["difficulty"] = difficulty
    return record


def write_rgb_png(path: Path, rgb: np.ndarray) -> None:
    """Write ``rgb`` (H, W, 3) uint8 as a PNG in ``path``'s existing folder, through a
    temporary name."""
    _write_png(path, cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2BGR))


def read_rgb_png(path: Path) -> np.ndarray:
    """The image in ``path`` (any format OpenCV reads), (H, W, 3) uint8 RGB.

    Raises
    ------
    ValueError
        If the file cannot be decoded as an image.
    """
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        raise ValueError(f"{path} is not an image")
    return np.ascontiguousarray(bgr[..., ::-1])


def _write_png(path: Path, image: np.ndarray) -> None:
    """Write ``image`` (as OpenCV holds it) as a PNG through a temporary name, so a killed
    run never leaves a truncated image under a frame's name."""
    ok, buf = cv2.imencode(".png", image)
    if not ok:
        raise ValueError(f"could not encode an image of shape {image.shape} as PNG for {path}")
    tmp = path.with_name(path.name + ".partial")
    tmp.write_bytes(buf.tobytes())
    tmp.replace(path)


def _write_json(path: Path, doc) -> None:
    tmp = path.with_name(path.name + ".partial")
    tmp.write_text(json.dumps(doc))
    tmp.replace(path)


@dataclass(frozen=True)
class LabelledFrame:
    """One frame of a dataset split, loaded: ``color`` (H, W, 3) uint8 RGB, ``depth`` (H, W)
    float32 metres (None in the inspection view), and its record (see the module docstring)."""

    color: np.ndarray
    depth: np.ndarray | None
    record: dict


def read_metadata(root: Path | str) -> dict:
    """A dataset folder's ``dataset.json``, checked; clear errors for anything else."""
    meta_path = Path(root) / "dataset.json"
    if not meta_path.is_file():
        raise FileNotFoundError(f"{root} is not a dataset folder (no dataset.json); render one "
                                "with `onionsort dataset`")
    try:
        meta = json.loads(meta_path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{meta_path} is not JSON ({exc})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise ValueError(f"{meta_path}: format must be {FORMAT!r}; got "
                         f"{meta.get('format') if isinstance(meta, dict) else meta!r}")
    return meta


ImageMap = Callable[[np.ndarray, dict], np.ndarray]
"""A change made to each colour image as it is read: ``(rgb (H, W, 3) uint8, its record) ->
rgb``, e.g. another camera for each session (the record names the session or line-up).
Depth is never passed through it."""


def read_split(root: Path | str, split: str, view: str = "camera", *,
               where: Callable[[dict], bool] | None = None,
               image_map: ImageMap | None = None) -> Iterator[LabelledFrame]:
    """Iterate the frames of one split of a dataset folder, in ``view`` (see :data:`VIEWS`);
    with ``where``, only the frames whose record it passes (the others are not read); with
    ``image_map``, each colour image as it gives it (:data:`ImageMap`; the files are not
    changed)."""
    root = Path(root)
    meta = read_metadata(root)
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}; got {split!r}")
    views = meta.get("views", ["camera"])
    if view not in views:
        raise ValueError(f"view must be one of the dataset's views {views}; got {view!r}")
    records: Iterable[dict] = json.loads((root / split / _LABELS[view]).read_text())
    for rec in records:
        if where is not None and not where(rec):
            continue
        color = cv2.imread(str(root / split / rec["color"]), cv2.IMREAD_COLOR)
        depth = (cv2.imread(str(root / split / rec["depth"]), cv2.IMREAD_UNCHANGED)
                 if "depth" in rec else None)
        if color is None or ("depth" in rec and depth is None):
            raise ValueError(f"{root / split}: frame {rec['color']} is missing or unreadable")
        color = cv2.cvtColor(color, cv2.COLOR_BGR2RGB)
        yield LabelledFrame(
            color=color if image_map is None else image_map(color, rec),
            depth=None if depth is None else depth.astype(np.float32) / 1000.0, record=rec,
        )


def read_records(root: Path | str, split: str, view: str = "camera") -> list[dict]:
    """The records of one split of a dataset folder in ``view``, without reading a frame."""
    root = Path(root)
    views = read_metadata(root).get("views", ["camera"])
    _check_split(split)
    if view not in views:
        raise ValueError(f"view must be one of the dataset's views {views}; got {view!r}")
    return json.loads((root / split / _LABELS[view]).read_text())


def dataset_task(root: Path | str) -> TaskDescription:
    """The task of a dataset folder's records: ``dataset.json``'s ``"task"``, or the
    onion-sorting task for a dataset written before the field."""
    return task_of(read_metadata(root), str(Path(root) / "dataset.json"))


def split_names(split: str) -> tuple[str, ...]:
    """The splits that ``split`` names: one of :data:`SPLITS`, or ``"all"`` for every one."""
    if split == "all":
        return SPLITS
    if split not in SPLITS:
        raise ValueError(f"split must be one of {(*SPLITS, 'all')}; got {split!r}")
    return (split,)


@dataclass(frozen=True)
class DatasetStep:
    """One complete step of a dataset session: its frames (phase order), the inspection view
    of each of them (None where a frame has none) and the first frame's record (labels)."""

    colors: list[np.ndarray]
    depths: list[np.ndarray]
    views: list[np.ndarray | None]
    record: dict

    @property
    def inspection(self) -> np.ndarray | None:
        """The inspection view of the step's first frame (None if it has none)."""
        return self.views[0] if self.views else None


def read_steps(root: Path | str, split: str, frames_per_step: int, *,
               session: int | None = None, image_map: ImageMap | None = None
               ) -> list[list[DatasetStep]]:
    """The complete steps of each session of a split (or ``"all"``), sessions in order
    (box-only frames, whose records have no ``state``, are left out); with
    ``session``, of that session of the split alone (a list of one, or none where it has no
    complete step), its frames alone read (:func:`split_sessions` names them); with
    ``image_map``, every colour image (frames and inspection views) changed by it as it is
    read (:func:`read_split`).

    Frames are grouped by :func:`recordings.session.steps.group_steps`; a step cut short at the end
    of the dataset (by its frame count) is left out.
    """
    def wanted(record: dict) -> bool:
        return session is None or record["session"] == session

    out = []
    for name in split_names(split):
        views = {(f.record["session"], f.record["frame"]): f.color
                 for f in read_split(root, name, view="inspection",
                                     where=lambda r: r.get("source", "human") == "human"
                                     and "state" in r and wanted(r), image_map=image_map)}
        steps = group_steps(read_split(root, name, where=lambda r: "state" in r and wanted(r),
                                       image_map=image_map),
                            step=lambda f: (f.record["session"], f.record["step"]),
                            phase=lambda f: f.record["phase"], frames_per_step=frames_per_step,
                            incomplete="drop", source=f"{root}/{name}")
        sessions: dict[int, list[DatasetStep]] = {}
        for (k, _), frames in steps:
            first = frames[0].record
            sessions.setdefault(k, []).append(DatasetStep(
                [f.color for f in frames], [f.depth for f in frames],
                [views.get((k, f.record["frame"])) for f in frames], first))
        out.extend(sessions[k] for k in sorted(sessions))
    return out


def split_sessions(root: Path | str, split: str) -> list[tuple[str, int]]:
    """``(split name, session)`` of each session of a split (or ``"all"``), in the order of
    :func:`read_steps`, from the labels alone (no frame is read)."""
    root = Path(root)
    read_metadata(root)
    return [(name, session) for name in split_names(split)
            for session in sorted({rec["session"] for rec in json.loads(
                (root / name / _LABELS["camera"]).read_text()) if "state" in rec})]
