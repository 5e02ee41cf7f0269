"""The state labels of labelled images as a CSV file, one row an image.

Columns: ``split`` (``train``, ``val``, ``test``; may be empty in a set without splits),
``image`` (the file name as the annotations give it), ``session``, ``step``, ``frame``
(integers), ``occluded`` (0 or 1), one column per factor of the task and ``action``, each value
named in the task's words (:class:`irl.domains.task.TaskDescription`: for onion sorting
``onion`` = ``conveyor``..., ``end_effector``, ``prediction`` = ``bad``..., ``action`` =
``pick``...). The task is the dataset's: nothing here names a factor.
"""

from __future__ import annotations

import csv
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from irl.domains.task import TaskDescription
from recordings.labels.annotated import BadAnnotations, split_name

__all__ = [
    "StatesRow",
    "csv_reader",
    "read_image",
    "read_split",
    "read_states",
    "states_columns",
    "write_csv",
    "write_states",
]


@dataclass(frozen=True)
class StatesRow:
    """One row: where the image is (``split``, ``image``), which session, step and frame it
    shows, whether the step was occluded, the value index of each factor and the action's."""

    split: str | None
    image: str
    session: int
    step: int
    frame: int
    occluded: bool
    factors: dict[str, int]
    action: int
    line: int = 0


def states_columns(task: TaskDescription) -> list[str]:
    """The CSV's columns for ``task``."""
    return ["split", "image", "session", "step", "frame", "occluded", *task.factor_names,
            "action"]


def read_states(path: Path | str, task: TaskDescription) -> list[StatesRow]:
    """The rows of a states CSV, each value checked against ``task``; a bad value is a
    :class:`recordings.labels.annotated.BadAnnotations` naming the file, the line and the column."""
    path = Path(path)
    reader = csv_reader(path, states_columns(task), "a states CSV")
    rows, seen = [], {}
    for row in reader:
        line = reader.line_num
        where = f"{path} line {line}"

        def integer(column: str, row=row, where=where) -> int:
            return _integer(row, column, where)

        def value(column: str, names: tuple[str, ...], row=row, where=where) -> int:
            return _value(row, column, names, where, task)

        split = read_split(row, where)
        occluded = (row["occluded"] or "").strip().lower()
        if occluded not in ("0", "1", "true", "false"):
            raise BadAnnotations(f"{where}: occluded must be 0 or 1; got {row['occluded']!r}")
        image = read_image(row, where, split, seen, line)
        rows.append(StatesRow(
            split=split, image=image, session=integer("session"), step=integer("step"),
            frame=integer("frame"), occluded=occluded in ("1", "true"),
            factors={f: value(f, task.factors[f]) for f in task.factor_names},
            action=value("action", task.action_names), line=line))
    return rows


def _integer(row: dict, column: str, where: str) -> int:
    try:
        return int(row[column])
    except (TypeError, ValueError):
        raise BadAnnotations(f"{where}: {column} must be an integer; got "
                             f"{row[column]!r}") from None


def _value(row: dict, column: str, names: tuple[str, ...], where: str,
           task: TaskDescription) -> int:
    text = (row[column] or "").strip()
    if text not in names:
        raise BadAnnotations(f"{where}: {column} {text!r} is not a value of the task "
                             f"{task.name!r} ({', '.join(names)})")
    return names.index(text)


def write_states(path: Path | str, rows: Iterable[StatesRow], task: TaskDescription) -> Path:
    """Write ``rows`` as a states CSV (through a temporary name)."""
    return write_csv(path, states_columns(task), (
        [r.split or "", r.image, r.session, r.step, r.frame, int(r.occluded),
         *(task.value_name(k, r.factors[k]) for k in task.factor_names),
         task.action_names[r.action]] for r in rows))


def csv_reader(path: Path, columns, kind: str) -> csv.DictReader:
    """A reader over the rows of the CSV at ``path``, which must have ``columns`` (``kind``
    names the file in the error, e.g. "a states CSV")."""
    try:
        with path.open(newline="") as f:
            lines = f.read().splitlines()
    except UnicodeDecodeError:
        raise BadAnnotations(f"{path} is not a text CSV file") from None
    reader = csv.DictReader(lines)
    missing = [c for c in columns if c not in (reader.fieldnames or [])]
    if missing:
        raise BadAnnotations(f"{path}: the columns {missing} are missing; {kind} has "
                             f"{', '.join(columns)}")
    return reader


def read_split(row: dict, where: str) -> str | None:
    """The row's ``split`` (None where empty: a set without splits)."""
    split_text = (row["split"] or "").strip()
    split = split_name(split_text) if split_text else None
    if split_text and split is None:
        raise BadAnnotations(f"{where}: split {split_text!r} is not train, val or test")
    return split


def read_image(row: dict, where: str, split: str | None, seen: dict, line: int) -> str:
    """The row's ``image``, refused where empty or where ``seen`` (``(split, image)`` -> line,
    updated) holds it already."""
    image = (row["image"] or "").strip()
    if not image:
        raise BadAnnotations(f"{where}: image is empty")
    if (split, image) in seen:
        raise BadAnnotations(f"{where}: image {image!r} already has a row (line "
                             f"{seen[split, image]})")
    seen[split, image] = line
    return image


def write_csv(path: Path | str, header, rows: Iterable[list]) -> Path:
    """Write ``header`` and ``rows`` as a CSV file at ``path`` (through a temporary name)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".partial")
    with tmp.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        writer.writerows(rows)
    tmp.replace(path)
    return path
