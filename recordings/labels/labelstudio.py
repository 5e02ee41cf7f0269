"""Label Studio's JSON formats: labelling tasks pre-annotated with predictions, and what a
person labelled, read back from Label Studio's JSON export.

One task per image: ``data`` holds the image's path (relative to the task file; serve the
folder through Label Studio's local file storage) and where it comes from (``session``,
``step``, ``frame``); ``predictions`` holds one prediction whose ``result`` lists a
``rectanglelabels`` region per box (``x``, ``y``, ``width``, ``height`` in percent of the
image, as Label Studio has them) and a ``choices`` answer per state label. The labelling
interface that reads it is :func:`labeling_config`.

Label Studio's *JSON* export is the same list of tasks, each with ``annotations``: what a
person made of it, in the same ``result`` layout. :func:`read_export` reads the last
annotation of each task that was not cancelled (a task without one was not labelled): its
boxes and class names as an :class:`~recordings.labels.annotated.AnnotatedImage`, its ``choices``
by name, and the task's ``data``.
"""

from __future__ import annotations

import json
import re
import urllib.parse
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from recordings.labels.annotated import AnnotatedImage, BadAnnotations

__all__ = ["LabelStudioTask", "LabelledTask", "labeling_config", "read_export", "write_tasks"]

#: Label Studio names an uploaded file ``<8 hex digits>-<its name>``.
_UPLOAD_PREFIX = re.compile(r"^[0-9a-f]{8}-")


@dataclass(frozen=True)
class LabelStudioTask:
    """One image to label: its path (relative), size, the predicted boxes (pixels), their
    class names and scores, the predicted state labels (``{name: value}``), an overall
    ``score`` and ``data`` to carry along (``session``, ``step``, ``frame``).

    ``score`` is the prediction's confidence, in [0, 1] as Label Studio requires; its Data
    Manager shows the task with the lowest score first."""

    image: str
    width: int
    height: int
    boxes: Sequence[Sequence[float]]
    labels: Sequence[str]
    scores: Sequence[float]
    choices: Mapping[str, str]
    score: float
    data: Mapping


def _task(t: LabelStudioTask, model: str) -> dict:
    if not 0.0 <= t.score <= 1.0:
        raise ValueError(f"a Label Studio prediction's score must be in [0, 1]; got {t.score} "
                         f"for {t.image}")
    result = []
    for k, ((x0, y0, x1, y1), label, score) in enumerate(zip(t.boxes, t.labels, t.scores,
                                                            strict=True)):
        result.append({
            "id": f"box{k}", "from_name": "label", "to_name": "image",
            "type": "rectanglelabels", "original_width": t.width,
            "original_height": t.height, "image_rotation": 0, "score": float(score),
            "value": {"x": 100 * x0 / t.width, "y": 100 * y0 / t.height,
                      "width": 100 * (x1 - x0) / t.width, "height": 100 * (y1 - y0) / t.height,
                      "rotation": 0, "rectanglelabels": [label]}})
    for name, value in t.choices.items():
        result.append({"id": name, "from_name": name, "to_name": "image", "type": "choices",
                       "value": {"choices": [value]}})
    return {"data": {"image": t.image, **t.data},
            "predictions": [{"model_version": model, "score": float(t.score),
                             "result": result}]}


def write_tasks(path: Path | str, tasks: Sequence[LabelStudioTask], model: str) -> Path:
    """Write ``tasks`` as a Label Studio import file (through a temporary name)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".partial")
    tmp.write_text(json.dumps([_task(t, model) for t in tasks], indent=1))
    tmp.replace(path)
    return path


def labeling_config(classes: Sequence[str], choices: Mapping[str, Sequence[str]]) -> str:
    """The labelling interface (Label Studio's XML) for the tasks: a box per onion with its
    class, and one single choice per state label."""
    lines = ["<View>", '  <Image name="image" value="$image"/>',
             '  <RectangleLabels name="label" toName="image">']
    lines += [f'    <Label value="{c}"/>' for c in classes]
    lines.append("  </RectangleLabels>")
    for name, values in choices.items():
        lines.append(f'  <Header value="{name}"/>')
        lines.append(f'  <Choices name="{name}" toName="image" choice="single">')
        lines += [f'    <Choice value="{v}"/>' for v in values]
        lines.append("  </Choices>")
    lines.append("</View>")
    return "\n".join(lines) + "\n"


@dataclass(frozen=True)
class LabelledTask:
    """One task of a Label Studio export as a person labelled it: the image with its boxes
    (``normalized``: in units of its width and height), the answer of each choice
    (``{from_name: value}``) and the task's ``data`` (``session``, ``step``, ``frame``...)."""

    image: AnnotatedImage
    choices: dict[str, str]
    data: dict


def _export_file(root: Path) -> Path:
    """The one JSON file at the top of ``root`` that is a Label Studio export: a list of
    tasks, each with ``data`` and ``annotations``."""
    found = []
    for path in sorted(root.glob("*.json")):
        try:
            doc = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError):
            continue
        if isinstance(doc, list) and doc and all(
                isinstance(t, dict) and "data" in t and "annotations" in t for t in doc):
            found.append(path)
    if not found:
        raise BadAnnotations(f"{root} holds no Label Studio JSON export at its top (a list of "
                             "tasks, each with data and annotations); export the project as "
                             "JSON into it")
    if len(found) > 1:
        raise BadAnnotations(f"{root} holds {len(found)} Label Studio exports "
                             f"({', '.join(p.name for p in found)}); keep one")
    return found[0]


def _image_path(root: Path, ref: str) -> Path:
    """The file a task's ``data.image`` names, in ``root``: a path relative to it (as
    ``label select`` writes it), a local-files URL (``/data/local-files/?d=...``) or an
    upload (``/data/upload/N/<hash>-NAME``), found as it is or by its name in ``images/``."""
    parsed = urllib.parse.urlparse(ref)
    given = urllib.parse.parse_qs(parsed.query).get("d", [parsed.path])[0]
    relative = Path(urllib.parse.unquote(given).lstrip("/"))
    names = [relative.name, _UPLOAD_PREFIX.sub("", relative.name)]
    candidates = [root / relative, *(root / "images" / n for n in names),
                  *(root / n for n in names)]
    for path in candidates:
        if path.is_file():
            return path
    return root / "images" / names[-1]


def read_export(root: Path | str) -> list[LabelledTask]:
    """The labelled tasks of the Label Studio JSON export at the top of ``root`` (see the
    module docstring), in its order; a file or value that is not so is a
    :class:`recordings.labels.annotated.BadAnnotations` naming it."""
    root = Path(root)
    if not root.is_dir():
        raise BadAnnotations(f"{root} is not a folder")
    path = _export_file(root)
    out = []
    for n, task in enumerate(json.loads(path.read_text())):
        where = f"{path} task {task.get('id', n)}"
        done = [a for a in task["annotations"]
                if isinstance(a, dict) and not a.get("was_cancelled")]
        if not done:
            continue
        data = task["data"] if isinstance(task["data"], dict) else {}
        ref = data.get("image")
        if not isinstance(ref, str) or not ref:
            raise BadAnnotations(f"{where}: data.image names no image")
        file = _image_path(root, ref)
        boxes, labels, choices = [], [], {}
        for r in done[-1].get("result", []):
            value = r.get("value", {}) if isinstance(r, dict) else {}
            if r.get("type") == "rectanglelabels":
                try:
                    x, y, w, h = (float(value[k]) / 100 for k in ("x", "y", "width", "height"))
                    (label,) = value["rectanglelabels"]
                except (KeyError, TypeError, ValueError):
                    raise BadAnnotations(f"{where}: a rectangle lacks x, y, width, height or "
                                         "its one label") from None
                if float(value.get("rotation", 0) or 0) != 0:
                    raise BadAnnotations(f"{where}: a rectangle is rotated; the dataset's "
                                         "boxes are upright")
                boxes.append((x, y, x + w, y + h))
                labels.append(str(label))
            elif r.get("type") == "choices":
                picked = value.get("choices")
                if not isinstance(picked, list) or len(picked) != 1:
                    raise BadAnnotations(f"{where}: choice {r.get('from_name')!r} must have one "
                                         f"answer; got {picked!r}")
                choices[str(r.get("from_name"))] = str(picked[0])
        image = AnnotatedImage(None, file.name, file, tuple(boxes), tuple(labels), where,
                               normalized=True)
        out.append(LabelledTask(image, choices, dict(data)))
    return out
