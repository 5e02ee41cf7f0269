"""A line-up's truth and what a robot did with it, as CSV files: P/R from a lab's own onions.

Onions are named by their line-up and their place in it, as in a line-ups CSV
(:mod:`recordings.labels.lineups_csv`): ``lineup`` and ``index`` (integers >= 0).

- **truth** (``truth.csv``): ``lineup``, ``index``, ``class`` (``good`` or ``blemished``):
  each onion's class, as a person sorted it by eye, or the simulator knows it;
- **tally** (``tally.csv``, beside ``evaluation.json``): ``lineup``, ``index``, ``fate``
  (``bin``, ``line``, ``tray``: binned, set back on the line, deferred to a person), ``call``
  (``good``, ``blemished``, or empty if the robot never inspected it), ``p_blemished`` (the
  inspection's probability, or empty) and ``deferred`` (1 where the fate is ``tray``, else 0).
  A person who counted the bins by hand writes one with ``call`` and ``p_blemished`` empty.

Every reader refuses a bad value with one message naming the file, the line and the column.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from irl.domains.onion_sorting import Prediction
from recordings.labels.annotated import BadAnnotations
from recordings.labels.states_csv import csv_reader, write_csv

__all__ = ["CLASSES", "FATES", "TALLY_COLUMNS", "TALLY_FILE", "TRUTH_COLUMNS", "TRUTH_FILE",
           "TallyRow", "read_tally", "read_truth", "tally_rows", "write_tally", "write_truth"]

TRUTH_FILE = "truth.csv"
TALLY_FILE = "tally.csv"
TRUTH_COLUMNS = ("lineup", "index", "class")
TALLY_COLUMNS = ("lineup", "index", "fate", "call", "p_blemished", "deferred")
#: The classes of the truth, good first.
CLASSES = ("good", "blemished")
#: An onion's fates (``robot.tally.FATES``, repeated: ``recordings`` imports no robot).
FATES = ("bin", "line", "tray")


@dataclass(frozen=True)
class TallyRow:
    """One onion of a tally: its ``fate``, the inspection's ``call`` (``"good"``,
    ``"blemished"``, None if never inspected) and ``p_blemished`` (None if none); ``line`` in
    the file, for messages."""

    lineup: int
    index: int
    fate: str
    call: str | None = None
    p_blemished: float | None = None
    line: int = 0

    @property
    def deferred(self) -> bool:
        """Whether the onion went to a person."""
        return self.fate == "tray"


def _onion(row: dict, where: str, seen: dict, line: int) -> tuple[int, int]:
    key = []
    for column in ("lineup", "index"):
        text = (row[column] or "").strip()
        try:
            value = int(text)
        except ValueError:
            value = -1
        if value < 0:
            raise BadAnnotations(f"{where}: {column} must be an integer >= 0; got "
                                 f"{row[column]!r}")
        key.append(value)
    onion = (key[0], key[1])
    if onion in seen:
        raise BadAnnotations(f"{where}: onion {onion[1]} of line-up {onion[0]} already has a "
                             f"row (line {seen[onion]})")
    seen[onion] = line
    return onion


def read_truth(path: Path | str) -> dict[tuple[int, int], bool]:
    """Each onion's class, ``(lineup, index) -> blemished``, from a truth CSV.

    Raises
    ------
    recordings.labels.annotated.BadAnnotations
        Naming the line and column of a bad value, a class that is neither good nor
        blemished, or an onion named twice; also if the file has no onion.
    FileNotFoundError
        If there is no such file.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such truth CSV (columns {', '.join(TRUTH_COLUMNS)})")
    reader = csv_reader(path, TRUTH_COLUMNS, "a truth CSV")
    truth, seen = {}, {}
    for row in reader:
        where = f"{path} line {reader.line_num}"
        onion = _onion(row, where, seen, reader.line_num)
        name = (row["class"] or "").strip().lower()
        if name not in CLASSES:
            raise BadAnnotations(f"{where}: class must be good or blemished; got "
                                 f"{row['class']!r}")
        truth[onion] = name == "blemished"
    if not truth:
        raise BadAnnotations(f"{path} names no onion")
    return truth


def write_truth(path: Path | str, truth: dict[tuple[int, int], bool]) -> Path:
    """Write ``truth`` (``(lineup, index) -> blemished``) as a truth CSV, in line-up order
    (through a temporary name)."""
    return write_csv(path, TRUTH_COLUMNS, ([lineup, index, CLASSES[int(bad)]]
                                           for (lineup, index), bad in sorted(truth.items())))


def read_tally(path: Path | str) -> list[TallyRow]:
    """The rows of a tally CSV.

    Raises
    ------
    recordings.labels.annotated.BadAnnotations
        Naming the line and column of a bad value (a fate other than bin, line or tray, a
        call other than good or blemished, a probability outside [0, 1], ``deferred`` that
        disagrees with the fate), an onion named twice, or a file with no onion.
    FileNotFoundError
        If there is no such file.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such tally CSV (columns "
                                f"{', '.join(TALLY_COLUMNS)})")
    reader = csv_reader(path, TALLY_COLUMNS, "a tally CSV")
    rows, seen = [], {}
    for row in reader:
        where = f"{path} line {reader.line_num}"
        lineup, index = _onion(row, where, seen, reader.line_num)
        fate = (row["fate"] or "").strip().lower()
        if fate not in FATES:
            raise BadAnnotations(f"{where}: fate must be one of {', '.join(FATES)}; got "
                                 f"{row['fate']!r}")
        call = (row["call"] or "").strip().lower() or None
        if call is not None and call not in CLASSES:
            raise BadAnnotations(f"{where}: call must be good, blemished or empty; got "
                                 f"{row['call']!r}")
        text = (row["p_blemished"] or "").strip()
        p_bad = None
        if text:
            try:
                p_bad = float(text)
            except ValueError:
                p_bad = math.nan
            if not 0.0 <= p_bad <= 1.0:
                raise BadAnnotations(f"{where}: p_blemished must be in [0, 1] or empty; got "
                                     f"{row['p_blemished']!r}")
        deferred = (row["deferred"] or "").strip().lower()
        if deferred not in ("0", "1", "true", "false"):
            raise BadAnnotations(f"{where}: deferred must be 0 or 1; got {row['deferred']!r}")
        if (deferred in ("1", "true")) != (fate == "tray"):
            raise BadAnnotations(f"{where}: deferred is {deferred} but the fate is {fate}; an "
                                 "onion is deferred exactly when its fate is tray")
        rows.append(TallyRow(lineup, index, fate, call, p_bad, line=reader.line_num))
    if not rows:
        raise BadAnnotations(f"{path} names no onion")
    return rows


def tally_rows(lineup: int, onions: Iterable) -> list[TallyRow]:
    """The rows of line-up ``lineup``'s ``onions``, each with its ``index``, ``fate``,
    ``perceived`` (a :class:`~irl.domains.onion_sorting.Prediction`, or None if never
    inspected) and ``p_blemished`` (``robot.tally.OnionOutcome``s: a sorting result's
    ``onions``, or a tally's ``outcomes()``)."""
    names = {Prediction.GOOD: "good", Prediction.BAD: "blemished"}
    return [TallyRow(int(lineup), int(o.index), o.fate,
                     None if o.perceived is None else names[Prediction(int(o.perceived))],
                     o.p_blemished) for o in onions]


def write_tally(path: Path | str, rows: Iterable[TallyRow]) -> Path:
    """Write ``rows`` as a tally CSV (through a temporary name)."""
    return write_csv(path, TALLY_COLUMNS, (
        [r.lineup, r.index, r.fate, r.call or "",
         "" if r.p_blemished is None else f"{r.p_blemished:.6g}", int(r.deferred)]
        for r in rows))
