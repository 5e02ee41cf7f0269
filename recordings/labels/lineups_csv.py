"""Where each of the robot's inspection views comes from, as a CSV file beside its images.

The Sawyer's views of its line-ups carry no state: what makes them the robot's is their
line-up, the onion's place in it and the view's number (a dataset record's ``source: robot``,
``lineup``, ``index``, ``view``). ``label export`` writes them to ``inspection/lineups.csv``
and ``label import`` reads them back, so the robot's views come back as the robot's.

Columns: ``split`` (``train``, ``val``, ``test``; may be empty in a set without splits),
``image`` (the file name as the annotations give it), ``lineup``, ``index``, ``view``
(integers >= 0).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from recordings.labels.annotated import BadAnnotations
from recordings.labels.states_csv import csv_reader, read_image, read_split, write_csv

__all__ = ["LINEUPS_COLUMNS", "LINEUPS_FILE", "LineupRow", "read_lineups", "write_lineups"]

LINEUPS_FILE = "lineups.csv"
LINEUPS_COLUMNS = ("split", "image", "lineup", "index", "view")


@dataclass(frozen=True)
class LineupRow:
    """One robot's view: where the image is (``split``, ``image``), its line-up, the onion's
    place in it and the view's number; ``line`` in the file, for messages."""

    split: str | None
    image: str
    lineup: int
    index: int
    view: int
    line: int = 0


def read_lineups(path: Path | str) -> list[LineupRow]:
    """The rows of a line-ups CSV; a bad value is a
    :class:`recordings.labels.annotated.BadAnnotations` naming the file, the line and the column."""
    reader = csv_reader(Path(path), LINEUPS_COLUMNS, "a line-ups CSV")
    rows, seen = [], {}
    for row in reader:
        where = f"{path} line {reader.line_num}"
        split = read_split(row, where)
        image = read_image(row, where, split, seen, reader.line_num)
        numbers = {}
        for column in ("lineup", "index", "view"):
            try:
                numbers[column] = int(row[column])
            except (TypeError, ValueError):
                numbers[column] = -1
            if numbers[column] < 0:
                raise BadAnnotations(f"{where}: {column} must be an integer >= 0; got "
                                     f"{row[column]!r}")
        rows.append(LineupRow(split, image, **numbers, line=reader.line_num))
    return rows


def write_lineups(path: Path | str, rows: Iterable[LineupRow]) -> Path:
    """Write ``rows`` as a line-ups CSV (through a temporary name)."""
    return write_csv(path, LINEUPS_COLUMNS,
                     ([r.split or "", r.image, r.lineup, r.index, r.view] for r in rows))
