"""Label Studio's JSON import format: labelling tasks pre-annotated with predictions.

One task per image: ``data`` holds the image's path (relative to the task file; serve the
folder through Label Studio's local file storage) and where it comes from (``session``,
``step``, ``frame``); ``predictions`` holds one prediction whose ``result`` lists a
``rectanglelabels`` region per box (``x``, ``y``, ``width``, ``height`` in percent of the
image, as Label Studio has them) and a ``choices`` answer per state label. The labelling
interface that reads it is :func:`labeling_config`.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

__all__ = ["LabelStudioTask", "labeling_config", "write_tasks"]


@dataclass(frozen=True)
class LabelStudioTask:
    """One image to label: its path (relative), size, the predicted boxes (pixels), their
    class names and scores, the predicted state labels (``{name: value}``), an overall
    ``score`` and ``data`` to carry along (``session``, ``step``, ``frame``)."""

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
