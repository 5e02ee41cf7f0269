"""YOLO (Ultralytics) detection labels: read a labelled image set, write one.

Layout: ``DIR/data.yaml`` names the classes (``names``, a list or ``{id: name}``) and the split
folders (``train``, ``val``, ``test``: image folders relative to ``path`` or to the file,
``images/<split>`` in Ultralytics' own layout, ``../train/images`` in Roboflow's). The labels of
``.../images/<split>/NAME.jpg`` are in ``.../labels/<split>/NAME.txt``, one box a line: ``class
cx cy w h``, the centre and size in units of the image's width and height (a polygon, ``class
x1 y1 x2 y2 ...``, gives its bounding box). An image without a label file shows no onion. A
``data.yaml`` that names one folder for every split, or none, holds a set without splits
(images in ``DIR/images/``).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import yaml

from recordings.labels.annotated import IMAGE_SUFFIXES, AnnotatedImage, BadAnnotations

__all__ = ["read_yolo", "write_data_yaml", "yolo_lines"]

DATA_FILE = "data.yaml"
_SPLIT_KEYS = {"train": "train", "val": "val", "valid": "val", "test": "test"}


def _data(root: Path) -> tuple[dict, Path]:
    path = next((root / n for n in (DATA_FILE, "data.yml") if (root / n).is_file()), None)
    if path is None:
        raise BadAnnotations(f"{root}: no {DATA_FILE} (the YOLO layout names its classes and "
                             "splits there)")
    try:
        doc = yaml.safe_load(path.read_text())
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise BadAnnotations(f"{path} is not YAML ({' '.join(str(exc).split())})") from None
    if not isinstance(doc, dict) or "names" not in doc:
        raise BadAnnotations(f"{path}: not a YOLO data file (it needs names)")
    return doc, path


def _class_names(doc: dict, path: Path) -> dict[int, str]:
    names = doc["names"]
    if isinstance(names, list):
        return {k: str(v) for k, v in enumerate(names)}
    if isinstance(names, dict) and all(isinstance(k, int) for k in names):
        return {k: str(v) for k, v in names.items()}
    raise BadAnnotations(f"{path}: names must be a list or a mapping of class ids to names; "
                         f"got {names!r}")


def _split_folders(doc: dict, path: Path) -> dict[str | None, Path]:
    """Split -> image folder; ``{None: folder}`` for a set without splits."""
    root = path.parent
    base = Path(doc["path"]) if doc.get("path") else root
    base = base if base.is_absolute() else root / base
    folders: dict[str | None, Path] = {}
    for key, split in _SPLIT_KEYS.items():
        entry = doc.get(key)
        if entry is None:
            continue
        if not isinstance(entry, str):
            raise BadAnnotations(f"{path}: {key} must name one image folder; got {entry!r}")
        rel = Path(entry)
        candidates = [base / rel, root / rel, root / Path(*[p for p in rel.parts if p != ".."])]
        folder = next((c for c in candidates if c.is_dir()), None)
        if folder is None:
            raise BadAnnotations(f"{path}: {key} names {entry!r}, which is not a folder of "
                                 "images")
        folders[split] = folder.resolve()
    if len(set(folders.values())) <= 1:
        folder = next(iter(folders.values()), root / "images")
        if not folder.is_dir():
            raise BadAnnotations(f"{path}: names no split folder, and {folder} does not exist")
        return {None: folder}
    return folders


def _labels_file(image: Path) -> Path:
    parts = list(image.parts)
    k = len(parts) - 1 - parts[::-1].index("images") if "images" in parts else None
    if k is None:
        return image.with_suffix(".txt")
    parts[k] = "labels"
    return Path(*parts).with_suffix(".txt")


def read_yolo(root: Path | str) -> list[AnnotatedImage]:
    """The labelled images of a YOLO folder (see the module docstring), split by split, each
    split's images in name order; boxes in units of the image's size (``normalized``)."""
    root = Path(root)
    if not root.is_dir():
        raise BadAnnotations(f"{root} is not a folder")
    doc, path = _data(root)
    names = _class_names(doc, path)
    out = []
    for split, folder in _split_folders(doc, path).items():
        for image in sorted(p for p in folder.rglob("*") if p.suffix.lower() in IMAGE_SUFFIXES):
            labels = _labels_file(image)
            boxes, classes = (_read_labels(labels, names) if labels.is_file() else ([], []))
            out.append(AnnotatedImage(split, image.relative_to(folder).as_posix(), image,
                                      tuple(boxes), tuple(classes), str(labels),
                                      normalized=True))
    return out


def _read_labels(path: Path, names: dict[int, str]) -> tuple[list, list]:
    boxes, classes = [], []
    for n, line in enumerate(path.read_text().splitlines(), start=1):
        fields = line.split()
        if not fields:
            continue
        where = f"{path} line {n}"
        if len(fields) != 5 and (len(fields) < 7 or len(fields) % 2 == 0):
            raise BadAnnotations(f"{where}: expected 5 numbers (class cx cy w h) or a polygon "
                                 f"(class x1 y1 x2 y2 x3 y3 ...); got {len(fields)}: {line!r}")
        try:
            cls, values = int(fields[0]), [float(v) for v in fields[1:]]
        except ValueError:
            raise BadAnnotations(f"{where}: expected an integer class and numbers; got "
                                 f"{line!r}") from None
        if cls not in names:
            raise BadAnnotations(f"{where}: class {cls} is not among the classes of "
                                 f"{DATA_FILE} ({', '.join(map(str, names))})")
        if len(values) == 4:
            cx, cy, w, h = values
            boxes.append((cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2))
        else:
            xs, ys = values[0::2], values[1::2]
            boxes.append((min(xs), min(ys), max(xs), max(ys)))
        classes.append(names[cls])
    return boxes, classes


def yolo_lines(boxes: Sequence[Sequence[float]], classes: Sequence[int], width: int,
               height: int) -> str:
    """The label file of one image: ``class cx cy w h`` per box, normalised by ``width`` and
    ``height``, with the digits that give the pixels back exactly."""
    lines = []
    for (x0, y0, x1, y1), cls in zip(boxes, classes, strict=True):
        cx, cy = (x0 + x1) / 2 / width, (y0 + y1) / 2 / height
        w, h = (x1 - x0) / width, (y1 - y0) / height
        lines.append(f"{int(cls)} " + " ".join(format(v, ".12g") for v in (cx, cy, w, h)))
    return "".join(line + "\n" for line in lines)


def write_data_yaml(root: Path | str, splits: Sequence[str], class_names: Sequence[str]) -> Path:
    """Write ``root/data.yaml`` of Ultralytics' layout (``images/<split>`` per split)."""
    path = Path(root) / DATA_FILE
    # no "path": Ultralytics then reads the folders relative to this file
    doc = {**{s: f"images/{s}" for s in splits},
           "names": dict(enumerate(class_names))}
    tmp = path.with_name(path.name + ".partial")
    tmp.write_text(yaml.safe_dump(doc, sort_keys=False))
    tmp.replace(path)
    return path
