"""COCO object-detection annotations: read a labelled image set, write one.

Layouts read (``DIR`` the folder given):

- COCO 2017: ``DIR/annotations/instances_<split>.json`` beside ``DIR/<split>/`` images (a year
  after the split, ``train2017``, is allowed; images may also sit in ``DIR/images/<split>/``);
- Roboflow: ``DIR/<split>/_annotations.coco.json`` beside the split's images (``valid`` is
  ``val``);
- without splits: one ``DIR/annotations/*.json`` that names no split (CVAT's
  ``instances_default.json``), ``DIR/_annotations.coco.json`` or ``DIR/result.json`` (Label
  Studio), images in ``DIR/images/`` or ``DIR/``.

A box is ``bbox: [x, y, width, height]`` in pixels; it becomes ``[x, y, x + width, y +
height]``. The writer gives the COCO 2017 layout with categories numbered from 1 in the
dataset's class order.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from recordings.labels.annotated import AnnotatedImage, BadAnnotations, split_name

__all__ = ["CocoImage", "read_coco", "write_coco"]

ROBOFLOW_FILE = "_annotations.coco.json"


@dataclass(frozen=True)
class CocoImage:
    """One image as the writer puts it in a COCO file: its ``file_name``, size, boxes
    ``[x_min, y_min, x_max, y_max]`` (pixels), the class index of each, and, for predictions,
    a ``score`` per box (None for labels)."""

    file_name: str
    width: int
    height: int
    boxes: Sequence[Sequence[float]]
    classes: Sequence[int]
    scores: Sequence[float] | None = None
    extra: dict | None = None


def _annotation_files(root: Path) -> list[tuple[str | None, Path, list[Path]]]:
    """``(split, annotation file, image folders to look in)`` of each annotation file."""
    found = []
    ann = root / "annotations"
    if ann.is_dir():
        for path in sorted(ann.glob("*.json")):
            stem = path.stem.removeprefix("instances_")
            split = split_name(re.sub(r"\d+$", "", stem))
            folders = [root / stem, root / "images" / stem, root / "images", root]
            found.append((split, path, folders))
    for sub in sorted(p for p in root.iterdir() if p.is_dir()):
        if (sub / ROBOFLOW_FILE).is_file() and split_name(sub.name):
            found.append((split_name(sub.name), sub / ROBOFLOW_FILE, [sub]))
    for name in (ROBOFLOW_FILE, "result.json"):
        if (root / name).is_file():
            found.append((None, root / name, [root / "images", root]))
    if not found:
        raise BadAnnotations(f"{root}: no COCO annotations (annotations/instances_<split>.json, "
                             f"<split>/{ROBOFLOW_FILE} or {ROBOFLOW_FILE})")
    if any(s is None for s, _, _ in found) and len(found) > 1:
        names = ", ".join(str(p.relative_to(root)) for _, p, _ in found)
        raise BadAnnotations(f"{root}: annotation files {names} do not name one split each "
                             "(train, val, test); keep one file for a set without splits")
    return found


def read_coco(root: Path | str) -> list[AnnotatedImage]:
    """The labelled images of a COCO folder (see the module docstring), in the order of
    their files and, in each, of their ``images`` list."""
    root = Path(root)
    if not root.is_dir():
        raise BadAnnotations(f"{root} is not a folder")
    out = []
    for split, path, folders in _annotation_files(root):
        out.extend(_read_file(path, split, folders, root))
    return out


def _read_file(path: Path, split: str | None, folders: list[Path], root: Path
               ) -> list[AnnotatedImage]:
    where = str(path)
    try:
        doc = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise BadAnnotations(f"{where} is not JSON ({exc})") from None
    if not (isinstance(doc, dict) and all(isinstance(doc.get(k), list)
                                          for k in ("images", "annotations", "categories"))):
        raise BadAnnotations(f"{where} is not COCO: it needs the lists images, annotations "
                             "and categories")
    try:
        names = {c["id"]: str(c["name"]) for c in doc["categories"]}
        images = {im["id"]: str(im["file_name"]) for im in doc["images"]}
    except (KeyError, TypeError) as exc:
        raise BadAnnotations(f"{where} is not COCO: a category or image lacks {exc}") from None
    boxes: dict = {k: [] for k in images}
    labels: dict = {k: [] for k in images}
    for n, a in enumerate(doc["annotations"]):
        if not isinstance(a, dict) or "bbox" not in a:
            raise BadAnnotations(f"{where}: annotation {n} is not a COCO box (no bbox)")
        bbox = a["bbox"]
        if (not isinstance(bbox, list) or len(bbox) != 4
                or not all(isinstance(v, int | float) for v in bbox)):
            raise BadAnnotations(f"{where}: annotation {n} has bbox {bbox!r}; expected 4 "
                                 "numbers [x, y, width, height]")
        if a.get("image_id") not in images:
            raise BadAnnotations(f"{where}: annotation {n} names image_id "
                                 f"{a.get('image_id')!r}, which is not among its images")
        if a.get("category_id") not in names:
            raise BadAnnotations(f"{where}: annotation {n} names category_id "
                                 f"{a.get('category_id')!r}, which is not among its categories")
        x, y, w, h = (float(v) for v in bbox)
        boxes[a["image_id"]].append((x, y, x + w, y + h))
        labels[a["image_id"]].append(names[a["category_id"]])
    out = []
    for key, file_name in images.items():
        candidates = [folder / file_name for folder in folders] + [
            folder / Path(file_name).name for folder in folders]
        found = next((p for p in candidates if p.is_file()), candidates[0])
        out.append(AnnotatedImage(split, file_name, found, tuple(boxes[key]),
                                  tuple(labels[key]), f"{where}"))
    return out


def coco_document(images: Iterable[CocoImage], class_names: Sequence[str]) -> dict:
    """A COCO object-detection document of ``images`` (ids from 1, in order)."""
    doc = {"info": {"description": "exported by onionsort"}, "licenses": [],
           "images": [], "annotations": [],
           "categories": [{"id": k + 1, "name": name, "supercategory": "onion"}
                          for k, name in enumerate(class_names)]}
    for image_id, image in enumerate(images, start=1):
        doc["images"].append({"id": image_id, "file_name": image.file_name,
                              "width": int(image.width), "height": int(image.height),
                              **(image.extra or {})})
        for k, (box, cls) in enumerate(zip(image.boxes, image.classes, strict=True)):
            x0, y0, x1, y1 = (float(v) for v in box)
            w, h = x1 - x0, y1 - y0
            ann = {"id": len(doc["annotations"]) + 1, "image_id": image_id,
                   "category_id": int(cls) + 1, "bbox": [_num(x0), _num(y0), _num(w), _num(h)],
                   "area": _num(w * h), "iscrowd": 0}
            if image.scores is not None:
                ann["score"] = float(image.scores[k])
            doc["annotations"].append(ann)
    return doc


def write_coco(path: Path | str, images: Iterable[CocoImage], class_names: Sequence[str]
               ) -> Path:
    """Write the COCO document of ``images`` to ``path`` (through a temporary name)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".partial")
    tmp.write_text(json.dumps(coco_document(images, class_names)))
    tmp.replace(path)
    return path


def _num(v: float) -> int | float:
    """An integral value as an int (pixel boxes stay exact in JSON), else the float."""
    return int(v) if float(v).is_integer() else float(v)
