"""The ``label`` stage: a dataset's labelled frames out to annotation tools, and back in.

:func:`export_labels` writes a dataset folder (``onionsort dataset``'s, or an imported one) in
the COCO 2017 or the Ultralytics YOLO layout, with its state labels in ``states.csv``
(:mod:`recordings.labels.states_csv`): the main camera's frames at the top of the folder, the
inspection views in ``inspection/`` in the same layout (the robot's line-up fields in
``inspection/lineups.csv``, :mod:`recordings.labels.lineups_csv`), depth as 16-bit PNG in
millimetres in ``depth/<split>/``. :func:`import_labels` reads such a folder, or what CVAT, Label
Studio, Roboflow or Ultralytics write, into a dataset folder that ``train``, ``calibrate`` and
``eval-perception`` read as they read a rendered one.

Import, in order: every annotation is read, every class name mapped and every state row
matched to its image before an image is written; the images are then read, their boxes
checked against their size, shrunk (with their boxes) to fit the detector's canvas where they
are larger, and written into a temporary folder renamed to ``out`` at the end. Bad input
fails with one message naming the file and what is wrong; nothing is written.

Example::

    from onionsort.stages.label import LabelImportConfig, import_labels
    import_labels(LabelImportConfig(source=Path("cvat-export"), format="coco",
                                    out=Path("runs/lab")))
"""

from __future__ import annotations

import contextlib
import logging
import shutil
import struct
import tempfile
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

from onionsort.configs.label import (
    IMPORT_FORMATS,
    LABEL_FORMATS,
    LabelExportConfig,
    LabelImportConfig,
)
from onionsort.stages.base import log_config

__all__ = ["FIT", "IMPORT_FORMATS", "LABEL_FORMATS", "LabelExportConfig", "LabelImportConfig",
           "export_labels", "import_labels"]

logger = logging.getLogger(__name__)

#: The detector's canvas (``perception.model.DetectorConfig``'s width and height, repeated so
#: that this stage loads no torch; a test checks they agree): larger images are shrunk to fit
#: it, keeping their aspect, by area averaging, as the detector's letterbox shrinks them.
FIT = (320, 256)
STATES_FILE = "states.csv"


def _check_new_folder(out: Path) -> None:
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise FileExistsError(f"{out} exists and is not an empty folder; choose a new --out")


@contextlib.contextmanager
def _staging(out: Path):
    """A temporary folder beside ``out``, renamed to ``out`` when the block ends well and
    removed when it fails: a failed run writes nothing."""
    _check_new_folder(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".partial", dir=out.parent))
    try:
        yield tmp
        _check_new_folder(out)
        if out.exists():
            out.rmdir()
        tmp.replace(out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


# -- export ----------------------------------------------------------------------------------


def _png_size(data: bytes, path: Path) -> tuple[int, int]:
    if data[:8] != b"\x89PNG\r\n\x1a\n" or data[12:16] != b"IHDR":
        raise ValueError(f"{path} is not a PNG image")
    width, height = struct.unpack(">II", data[16:24])
    return int(width), int(height)


def export_labels(config: LabelExportConfig) -> dict:
    """Write ``config.data`` into ``config.out`` in ``config.format``'s layout.

    Returns ``{view: {split: images}}`` and ``"boxes"`` (per view, per class name).
    """
    from recordings.labels.coco import CocoImage, write_coco
    from recordings.labels.dataset import CLASSES, SPLITS, dataset_task, read_metadata, read_records
    from recordings.labels.lineups_csv import LINEUPS_FILE, LineupRow, write_lineups
    from recordings.labels.states_csv import StatesRow, write_states
    from recordings.labels.yolo import write_data_yaml, yolo_lines

    log_config("label export", config)
    meta = read_metadata(config.data)
    task = dataset_task(config.data)
    classes = meta.get("classes", list(CLASSES))
    summary: dict = {"images": {}, "boxes": {}}
    with _staging(config.out) as tmp:
        for view in meta.get("views", ["camera"]):
            base = tmp if view == "camera" else tmp / "inspection"
            rows, lineups, counts, boxes = [], [], {}, dict.fromkeys(classes, 0)
            for split in SPLITS:
                records = read_records(config.data, split, view)
                coco = []
                images = (base / split if config.format == "coco"
                          else base / "images" / split)
                images.mkdir(parents=True, exist_ok=True)
                for rec in records:
                    source = config.data / split / rec["color"]
                    png = source.read_bytes()
                    width, height = _png_size(png, source)
                    name = Path(rec["color"]).name
                    (images / name).write_bytes(png)
                    if "depth" in rec:
                        (base / "depth" / split).mkdir(parents=True, exist_ok=True)
                        shutil.copyfile(config.data / split / rec["depth"],
                                        base / "depth" / split / name)
                    if config.format == "coco":
                        coco.append(CocoImage(name, width, height, rec["boxes"], rec["classes"]))
                    else:
                        labels = base / "labels" / split
                        labels.mkdir(parents=True, exist_ok=True)
                        (labels / Path(name).with_suffix(".txt")).write_text(
                            yolo_lines(rec["boxes"], rec["classes"], width, height))
                    for c in rec["classes"]:
                        boxes[classes[c]] += 1
                    if "state" in rec:
                        rows.append(StatesRow(split, name, rec["session"], rec["step"],
                                              rec["frame"], bool(rec["occluded"]),
                                              {f: int(rec[f]) for f in task.factor_names},
                                              int(rec["action"])))
                    if rec.get("source") == "robot":
                        lineups.append(LineupRow(split, name, int(rec["lineup"]),
                                                 int(rec["index"]), int(rec.get("view", 0))))
                if config.format == "coco":
                    write_coco(base / "annotations" / f"instances_{split}.json", coco, classes)
                counts[split] = len(records)
            if config.format == "yolo":
                write_data_yaml(base, SPLITS, classes)
            if rows:
                write_states(base / STATES_FILE, rows, task)
            if lineups:
                write_lineups(base / LINEUPS_FILE, lineups)
            summary["images"][view], summary["boxes"][view] = counts, boxes
    return summary


# -- import ----------------------------------------------------------------------------------


def _default(given: Path | None, path: Path, *, folder: bool) -> Path | None:
    if given is not None:
        if not (given.is_dir() if folder else given.is_file()):
            raise FileNotFoundError(f"{given}: no such {'folder' if folder else 'file'}")
        return given
    return path if (path.is_dir() if folder else path.is_file()) else None


@dataclass
class _Item:
    """An image to import, with its split and state row once matched."""

    image: object  # recordings.labels.annotated.AnnotatedImage
    view: str
    split: str | None
    row: object = None  # recordings.labels.states_csv.StatesRow
    phase: int = 0
    lineup: object = None  # recordings.labels.lineups_csv.LineupRow: a robot's view


def import_labels(config: LabelImportConfig) -> dict:
    """Read ``config.source`` into a new dataset folder ``config.out``.

    Returns ``{"images": {view: {split: n}}, "with_states": {view: n}, "depth": n,
    "sessions": {split: n}}``.
    """
    from irl.domains.onion_sorting import SORTING_TASK
    from recordings.labels.annotated import BadAnnotations
    from recordings.labels.dataset import CLASSES
    from recordings.labels.lineups_csv import LINEUPS_FILE, read_lineups
    from recordings.labels.states_csv import read_states

    log_config("label import", config)
    task = SORTING_TASK
    if not config.source.is_dir():
        raise FileNotFoundError(f"{config.source}: no such folder")
    _check_new_folder(config.out)
    names = {config.classes.get(c, c): k for k, c in enumerate(CLASSES)}
    sets = {"camera": (config.source, _default(config.states, config.source / STATES_FILE,
                                                folder=False))}
    inspection = _default(config.inspection, config.source / "inspection", folder=True)
    if inspection is not None:
        sets["inspection"] = (inspection, _default(None, inspection / STATES_FILE,
                                                   folder=False))
    depth = _default(config.depth, config.source / "depth", folder=True)
    known = ", ".join(f"{CLASSES[k]}={n}" for n, k in names.items())
    items: list[_Item] = []
    for view, (folder, states) in sets.items():
        images, rows = _read_set(folder, config.format, task)
        for image in images:
            for label in image.labels:
                if label not in names:
                    raise BadAnnotations(
                        f"{image.source}: class {label!r} of {image.name} is not mapped to a "
                        f"class of the dataset ({known}); map it with --classes "
                        "good=NAME,blemished=NAME")
        mine = [_Item(image, view, image.split, row)
                for image, row in zip(images, rows, strict=True)]
        if states is not None:
            _match_rows(mine, read_states(states, task), states)
        lineups = folder / LINEUPS_FILE
        if view == "inspection" and lineups.is_file():
            _match_rows(mine, read_lineups(lineups), lineups, "lineup")
        items.extend(mine)
    _assign_splits(items, config.val, config.test)
    steps: dict = defaultdict(list)
    for item in items:
        if item.row is not None:
            steps[item.view, item.row.session, item.row.step].append(item)
    for members in steps.values():  # a frame's phase: its place in its step
        for phase, item in enumerate(sorted(members, key=lambda i: i.row.frame)):
            item.phase = phase
    frames_per_step = max((len(m) for (view, _, _), m in steps.items() if view == "camera"),
                          default=3)
    return _write(config, items, task, depth, frames_per_step, names)


def _read_set(folder: Path, fmt: str, task) -> tuple[list, list]:
    """The annotated images of ``folder`` in ``fmt``, and the state row each carries (None
    each, but for Label Studio's choices: :func:`_choices_row`)."""
    from recordings.labels.coco import read_coco
    from recordings.labels.labelstudio import read_export
    from recordings.labels.yolo import read_yolo

    if fmt != "labelstudio":
        images = (read_coco if fmt == "coco" else read_yolo)(folder)
        return images, [None] * len(images)
    tasks = read_export(folder)
    return [t.image for t in tasks], [_choices_row(t, task) for t in tasks]


def _choices_row(labelled, task):
    """The state row of a Label Studio task (:class:`recordings.labels.labelstudio.LabelledTask`)
    from its choices (``occluded`` yes or no, each factor and ``action`` in the task's
    words) and its data's ``session``, ``step`` and ``frame``; None where it has no state
    choice (box-only)."""
    from recordings.labels.annotated import BadAnnotations
    from recordings.labels.states_csv import StatesRow

    names = {**{f: task.factors[f] for f in task.factor_names}, "action": task.action_names,
             "occluded": ("no", "yes")}
    where = labelled.image.source
    given = {k: v for k, v in labelled.choices.items() if k in names}
    if not given:
        return None
    missing = [k for k in names if k not in given]
    if missing:
        raise BadAnnotations(f"{where}: the state choices {missing} are not answered; answer "
                             f"all of {', '.join(names)} or none")
    for k, v in given.items():
        if v not in names[k]:
            raise BadAnnotations(f"{where}: {k} {v!r} is not a value of the task "
                                 f"{task.name!r} ({', '.join(names[k])})")
    try:
        session, step, frame = (int(labelled.data[k]) for k in ("session", "step", "frame"))
    except (KeyError, TypeError, ValueError):
        raise BadAnnotations(f"{where}: a task with state choices needs data.session, "
                             "data.step and data.frame (integers)") from None
    return StatesRow(None, labelled.image.name, session, step, frame,
                     given["occluded"] == "yes",
                     {f: names[f].index(given[f]) for f in task.factor_names},
                     names["action"].index(given["action"]))


def _match_rows(items: list[_Item], rows: list, path: Path, attr: str = "row") -> None:
    """Give each item its state row (``attr`` "row") or its robot's line-up row ("lineup"):
    by ``(split, image)``, or by the image alone where the row names no split (or the set has
    none). A row for no image, and a robot's view with a state, are errors."""
    from recordings.labels.annotated import BadAnnotations

    by_key = {(i.split, i.image.name): i for i in items}
    by_name: dict = defaultdict(list)
    for i in items:
        by_name[i.image.name].append(i)
    for row in rows:
        if row.split is not None and (row.split, row.image) in by_key:
            item = by_key[row.split, row.image]
        elif (row.split is None or (items and items[0].split is None)) \
                and len(by_name[row.image]) == 1:
            item = by_name[row.image][0]
        else:
            where = f" of split {row.split}" if row.split else ""
            raise BadAnnotations(f"{path} line {row.line}: image {row.image!r}{where} is not "
                                 "among the annotated images")
        if getattr(item, attr) is not None:
            raise BadAnnotations(f"{path} line {row.line}: image {row.image!r} already has a "
                                 f"row (line {getattr(item, attr).line})")
        if item.row is not None and attr == "lineup":
            raise BadAnnotations(f"{path} line {row.line}: image {row.image!r} has a state "
                                 "row; a robot's view has none")
        setattr(item, attr, row)


def _assign_splits(items: list[_Item], val: float, test: float) -> None:
    """Split a set without splits as ``onionsort dataset`` does: by session (each session's
    frames, of both views, in one split), sessions in order; box-only images in order, by the
    same shares."""
    from onionsort.stages.dataset import split_plan

    unsplit = [i for i in items if i.split is None]
    if not unsplit:
        return
    sessions = sorted({i.row.session for i in unsplit if i.row is not None})
    if sessions:
        if len(sessions) < 3:
            raise ValueError(f"the labelled frames hold {len(sessions)} session(s), which "
                             "cannot fill three splits (train, val, test); label frames of 3 "
                             "sessions or more, or split the set into train, val and test")
        plan = dict(zip(sessions, split_plan(len(sessions), val, test), strict=True))
        for i in unsplit:
            if i.row is not None:
                i.split = plan[i.row.session]
    for view in ("camera", "inspection"):
        rest = [i for i in unsplit if i.row is None and i.view == view]
        plan = ["train"] * len(rest) if len(rest) < 3 else split_plan(len(rest), val, test)
        for i, split in zip(rest, plan, strict=True):
            i.split = split


def _round(v: float) -> int | float:
    v = round(float(v), 3)
    return int(v) if v.is_integer() else v


def _depth_file(depth: Path | None, item: _Item) -> Path | None:
    if depth is None or item.view != "camera":
        return None
    stem = Path(item.image.name).with_suffix(".png").name
    for path in (depth / (item.split or "") / stem, depth / stem):
        if path.is_file():
            return path
    return None


def _write(config: LabelImportConfig, items: list[_Item], task, depth: Path | None,
           frames_per_step: int, names: dict) -> dict:
    from onionsort import __version__
    from recordings.labels.annotated import load_image
    from recordings.labels.dataset import SPLITS, VIEWS, DatasetWriter

    def order(i: _Item):
        return (0, i.row.session, i.row.frame, "") if i.row else (1, 0, 0, i.image.name)

    counts = {v: dict.fromkeys(SPLITS, 0) for v in VIEWS}
    with_states, with_depth = dict.fromkeys(VIEWS, 0), 0
    sessions = {s: sorted({i.row.session for i in items if i.row and i.split == s})
                for s in SPLITS}
    metadata = {
        "seed": None, "frames": sum(i.view == "camera" for i in items),
        "sessions": len({i.row.session for i in items if i.row}),
        "config": {"frames_per_step": frames_per_step, "difficulty": "lab"},
        "software": f"onionsort {__version__}",
        "imported": {"format": config.format, "from": config.source.resolve().name},
    }
    with _staging(config.out) as tmp:
        writer = DatasetWriter(tmp, metadata, task=task)
        for view in VIEWS:
            for split in SPLITS:
                for item in sorted((i for i in items if i.view == view and i.split == split),
                                   key=order):
                    image = item.image
                    loaded = load_image(image, FIT, _depth_file(depth, item))
                    with_depth += loaded.depth_mm is not None
                    record = {"source": "human", "image": image.name,
                              "boxes": [[_round(v) for v in b] for b in loaded.boxes],
                              "classes": [names[label] for label in image.labels]}
                    if item.row is not None:
                        row = item.row
                        record.update({"state": task.encode(row.factors), **row.factors,
                                       "action": row.action, "occluded": row.occluded,
                                       "phase": item.phase, "step": row.step,
                                       "session": row.session, "frame": row.frame})
                        with_states[view] += 1
                    if item.lineup is not None:
                        record.update({"source": "robot", "lineup": item.lineup.lineup,
                                       "index": item.lineup.index, "view": item.lineup.view})
                    writer.add_image(split, view, record, loaded.color,
                                     depth_mm=loaded.depth_mm, png=loaded.png)
                    counts[view][split] += 1
        writer.close()
    logger.info("imported %s", counts)
    return {"images": counts, "with_states": with_states, "depth": with_depth,
            "sessions": {s: len(v) for s, v in sessions.items()}}
