"""Recorded line-ups: a robot's views of a line of onions, recorded once, replayed by any policy.

A recording is a folder of inspection views laid out as ``label export`` writes
``inspection/`` (the images, by split or not, and ``lineups.csv``: each image's ``lineup``,
``index`` and ``view``; :mod:`recordings.labels.lineups_csv`), with a truth CSV that gives each
onion's class (:mod:`recordings.labels.sorting_csv`). :func:`evaluate_lineup` replays a policy
on it (:class:`robot.replay.ReplayedLineup`, through the sorting loop every cell goes through)
and writes what ``evaluate`` writes of a simulated run: ``evaluation.json`` and ``tally.csv``.
:class:`LineupRecorder` records one from a simulated run (``evaluate --record-lineup DIR``):
every view of every onion, ``lineups.csv`` and the simulator's ``truth.csv``.
:func:`score` counts a tally against a truth (``onionsort score``).

A line-up's onions are its indices 0 to the highest one: each must have views, the truth must
name exactly them, and a tally must be of the same onions; every mismatch is one message that
names it, before anything is written.
"""

from __future__ import annotations

import logging
import shutil
import tempfile
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from onionsort.configs.evaluate import EvaluateConfig
from onionsort.configs.score import ScoreConfig
from onionsort.stages.base import check_output_folder, write_json

__all__ = ["LineupRecorder", "RecordedLineup", "ScoreConfig", "evaluate_lineup", "match_truth",
           "read_recording", "score"]

logger = logging.getLogger(__name__)

#: Where a recording's images may be, relative to its folder, for a row of split ``{split}``
#: (COCO's layout, YOLO's, and a set without splits).
_IMAGE_PLACES = ("{split}", "images/{split}", "", "images")


@dataclass(frozen=True)
class RecordedLineup:
    """One recorded line-up: its number and each onion's views (image files, in view order)."""

    lineup: int
    views: tuple[tuple[Path, ...], ...]

    @property
    def n_onions(self) -> int:
        return len(self.views)

    def load(self, index: int) -> list[np.ndarray]:
        """The views of onion ``index``, each (h, w, 3) uint8 RGB.

        Raises
        ------
        ValueError
            Naming a file that is not an image.
        """
        from recordings.labels.dataset import read_rgb_png

        out = []
        for path in self.views[index]:
            try:
                out.append(read_rgb_png(path))
            except ValueError as err:
                raise ValueError(f"{err} (onion {index} of line-up {self.lineup})") from None
        return out


def _find_image(folder: Path, split: str | None, image: str) -> Path | None:
    for place in _IMAGE_PLACES:
        if "{split}" in place and split is None:
            continue
        path = folder / place.format(split=split) / image
        if path.is_file():
            return path
    return None


def read_recording(source: Path) -> list[RecordedLineup]:
    """The line-ups of the recording ``source`` (a folder with ``lineups.csv``, or one whose
    ``inspection/`` has it), in line-up order.

    Raises
    ------
    FileNotFoundError
        If there is no such folder, no ``lineups.csv``, or an image it names.
    ValueError
        If ``lineups.csv`` is malformed, names a view twice, or a line-up has an onion without
        views.
    """
    from recordings.labels.lineups_csv import LINEUPS_FILE, read_lineups

    source = Path(source)
    if not source.is_dir():
        raise FileNotFoundError(f"--lineup {source}: no such folder")
    folder = source
    if not (folder / LINEUPS_FILE).is_file() and (source / "inspection" / LINEUPS_FILE).is_file():
        folder = source / "inspection"
    path = folder / LINEUPS_FILE
    if not path.is_file():
        raise FileNotFoundError(f"--lineup {source} holds no {LINEUPS_FILE} (a recorded line-up "
                                f"is a folder of views with {LINEUPS_FILE}, as `onionsort "
                                "label export` writes inspection/ or `evaluate --record-lineup` "
                                "writes)")
    rows = read_lineups(path)
    if not rows:
        raise ValueError(f"{path} names no view")
    views: dict[int, dict[int, dict[int, tuple[Path, int]]]] = defaultdict(lambda: defaultdict(
        dict))
    for row in rows:
        found = _find_image(folder, row.split, row.image)
        if found is None:
            raise FileNotFoundError(f"{path} line {row.line}: image {row.image!r} is not in "
                                    f"{folder}")
        onion = views[row.lineup][row.index]
        if row.view in onion:
            raise ValueError(f"{path} line {row.line}: view {row.view} of onion {row.index} of "
                             f"line-up {row.lineup} already has a row (line "
                             f"{onion[row.view][1]})")
        onion[row.view] = (found, row.line)
    out = []
    for lineup in sorted(views):
        onions = views[lineup]
        last = max(onions)
        missing = [i for i in range(last + 1) if i not in onions]
        if missing:
            raise ValueError(f"{path}: onion {_spans(missing)} of line-up {lineup} has no views "
                             f"(a line-up's onions are 0 to {last}, each with its views)")
        out.append(RecordedLineup(lineup, tuple(
            tuple(onions[i][v][0] for v in sorted(onions[i])) for i in range(last + 1))))
    return out


def _spans(numbers) -> str:
    """``[0, 1, 2, 5]`` as ``"0-2, 5"``."""
    numbers = sorted(numbers)
    parts, start = [], None
    for k, n in enumerate(numbers):
        if start is None:
            start = n
        if k + 1 == len(numbers) or numbers[k + 1] != n + 1:
            parts.append(str(start) if start == n else f"{start}-{n}")
            start = None
    return ", ".join(parts)


def _onions(keys) -> str:
    """``{(lineup, index)}`` as ``"line-up 0: onions 0-9; line-up 3: onion 4"``."""
    by_lineup: dict[int, list[int]] = defaultdict(list)
    for lineup, index in keys:
        by_lineup[lineup].append(index)
    return "; ".join(f"line-up {lineup}: onion{'s' if len(idx) > 1 else ''} {_spans(idx)}"
                     for lineup, idx in sorted(by_lineup.items()))


def match_truth(onions: set[tuple[int, int]], truth: dict[tuple[int, int], bool],
                truth_path: Path, what: str) -> None:
    """Refuse a truth that does not name exactly ``onions`` (``(lineup, index)``): ``what``
    names where they come from (the recording, a tally).

    Raises
    ------
    ValueError
        Naming the onions the truth misses, or those it names that ``what`` does not hold.
    """
    missing, unknown = onions - set(truth), set(truth) - onions
    if missing:
        raise ValueError(f"{truth_path} gives no class for {_onions(missing)} of {what}; the "
                         "truth must name every onion")
    if unknown:
        raise ValueError(f"{truth_path} names {_onions(unknown)}, which {what} does not hold")


def evaluate_lineup(config: EvaluateConfig, actions: np.ndarray, doc: dict,
                    confidence: np.ndarray | None, models=None):
    """Replay the policy ``actions`` (48,) on the recorded line-up(s) of ``config.lineup``,
    each onion's class from ``config.truth``; write ``evaluation.json`` and ``tally.csv``
    into ``config.folder``. Returns ``(result, summary)``: the line-ups' pooled
    :class:`robot.tally.SortingResult` and the dict written."""
    from recordings.labels.sorting_csv import TALLY_FILE, read_truth, tally_rows, write_tally
    from robot.cell import SortingRun, ViewReader
    from robot.replay import ReplayedLineup
    from robot.tally import SortingResult

    recording = read_recording(config.lineup)
    truth = read_truth(config.truth)
    match_truth({(r.lineup, i) for r in recording for i in range(r.n_onions)}, truth,
                config.truth, f"the line-up(s) of {config.lineup}")
    folder = check_output_folder(config.folder, "--out" if config.out is not None
                                 else "RUN_DIR")
    classify, inspector = _classifier(config, models)
    reader = ViewReader(classify, max_views=config.inspection_views,
                        stop_when_settled=not config.every_view)
    results, rows = [], []
    for lineup in recording:
        classes = np.array([truth[lineup.lineup, i] for i in range(lineup.n_onions)])
        run = SortingRun(ReplayedLineup(lineup.n_onions, lineup.load), lineup.n_onions,
                         reader, truth=classes, confidence=confidence,
                         defer_below=config.defer_below or 0.0)
        run.run(actions)
        result = run.result()
        logger.info("line-up %d: %s", lineup.lineup, result.table().replace("\n", "; "))
        results.append((lineup.lineup, result))
        rows.extend(tally_rows(lineup.lineup, result.onions))
    pooled = SortingResult(
        tp=sum(r.tp for _, r in results), fp=sum(r.fp for _, r in results),
        tn=sum(r.tn for _, r in results), fn=sum(r.fn for _, r in results),
        n_steps=sum(r.n_steps for _, r in results),
        undecided=sum(r.undecided for _, r in results),
        onions=tuple(o for _, r in results for o in r.onions),
        deferred=sum(r.deferred for _, r in results))
    summary = {"method": doc.get("method"), "policy": config.policy,
               "lineup": str(config.lineup), "truth": str(config.truth),
               "lineups": [n for n, _ in results],
               **_inspection_summary(config, inspector), **pooled.to_dict()}
    if len(results) > 1:
        summary["per_lineup"] = [{"lineup": n, **{k: v for k, v in r.to_dict().items()
                                                   if k != "onions"}} for n, r in results]
    write_tally(folder / TALLY_FILE, rows)
    write_json(folder / "evaluation.json", summary)
    return pooled, summary


def _classifier(config: EvaluateConfig, models=None, level: str | None = None):
    """``(classify, inspector)``: what reads the views, and the detector's inspection (None
    for ground truth); the robot's P(blemished) calibrated for a line of difficulty ``level``
    (:meth:`~onionsort.stages.models.PerceptionModels.at_level`; None: the pooled
    calibration, as on a recorded line-up, whose level is not known)."""
    if config.ground_truth_inspection:
        return "ground-truth", None
    from onionsort.stages.models import PerceptionModels

    loaded = PerceptionModels.load(config.models, config.device) if models is None else models
    loaded = loaded.at_level(level)
    inspector = loaded.inspector(rule=config.fusion, threshold=config.threshold,
                                 camera="robot")
    return inspector, inspector


def _inspection_summary(config: EvaluateConfig, inspector) -> dict:
    """The inspection's settings, as ``evaluation.json`` records them."""
    return {"inspection": ("ground truth" if config.ground_truth_inspection else
                           "detector + inspection classifier"),
            "inspection_views": config.inspection_views, "every_view": config.every_view,
            "defer_below": config.defer_below,
            "threshold": None if inspector is None else inspector.threshold,
            "fusion": None if inspector is None else inspector.rule,
            "fused_calibration": None if inspector is None else _calibration(inspector)}


def _calibration(inspector) -> list | None:
    """The calibration ``[low, high, form]`` (under ``"powers"``, the two powers after it) the
    inspector's fused probability carries (None: uncalibrated)."""
    applied = inspector.classifier.fused_calibration.get(inspector.rule)
    return None if applied is None else list(applied)


class LineupRecorder:
    """Records a simulated run's line-up into a folder ``evaluate --lineup`` replays: every
    view of every onion as a PNG under ``images/``, ``lineups.csv`` and the simulator's
    ``truth.csv``. Written into a temporary folder beside ``out``, renamed to ``out`` by
    :meth:`finish`; :meth:`discard` removes it.

    Parameters
    ----------
    out : Path
        The folder to record into (new, or empty).
    lineup : int
        The line-up's number (a simulated line-up's is its seed).
    """

    def __init__(self, out: Path, lineup: int) -> None:
        out = self.check(out)
        out.parent.mkdir(parents=True, exist_ok=True)
        self.out, self.lineup = out, int(lineup)
        self._tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".partial",
                                          dir=out.parent))
        (self._tmp / "images").mkdir()
        self._rows: list = []
        self.views: dict[int, int] = {}

    @staticmethod
    def check(out: Path) -> Path:
        """``out``, once it is a folder to record into (new, or empty).

        Raises
        ------
        FileExistsError
            If it is a file or a folder with files.
        """
        out = Path(out)
        if out.exists() and (not out.is_dir() or any(out.iterdir())):
            raise FileExistsError(f"--record-lineup {out} exists and is not an empty folder; "
                                  "choose a new one")
        return out

    def on_step(self, event) -> None:
        """Keep the views an evaluation step (:class:`robot.evaluation.EvaluationStep`) took."""
        from recordings.labels.dataset import write_rgb_png
        from recordings.labels.lineups_csv import LineupRow

        if not event.views:
            return
        for k, rgb in enumerate(event.views):
            name = f"lineup{self.lineup}-onion{event.onion:03d}-view{k}.png"
            write_rgb_png(self._tmp / "images" / name, rgb)
            self._rows.append(LineupRow(None, name, self.lineup, int(event.onion), k))
        self.views[int(event.onion)] = len(event.views)

    def finish(self, blemished: np.ndarray) -> Path:
        """Write ``lineups.csv`` and ``truth.csv`` (``blemished`` (n_onions,): the classes)
        and rename the folder to ``out``.

        Raises
        ------
        ValueError
            If an onion was never inspected (the policy skipped it): a recorded line-up needs
            every onion's views; record with ``--policy expert``.
        """
        from recordings.labels.lineups_csv import LINEUPS_FILE, write_lineups
        from recordings.labels.sorting_csv import TRUTH_FILE, write_truth

        missing = [i for i in range(len(blemished)) if i not in self.views]
        if missing:
            raise ValueError(f"--record-lineup needs every onion's views; the policy never "
                             f"inspected onion {_spans(missing)}: record with --policy expert")
        write_lineups(self._tmp / LINEUPS_FILE, sorted(self._rows,
                                                       key=lambda r: (r.index, r.view)))
        write_truth(self._tmp / TRUTH_FILE, {(self.lineup, i): bool(b)
                                             for i, b in enumerate(blemished)})
        if self.out.exists():
            self.out.rmdir()
        self._tmp.replace(self.out)
        return self.out

    def discard(self) -> None:
        """Remove what was recorded (a failed run records nothing)."""
        shutil.rmtree(self._tmp, ignore_errors=True)


def score(config: ScoreConfig):
    """TP/FP/TN/FN, precision and recall with their 95% intervals, and the deferred onions, of
    the tally ``config.tally`` against the truth ``config.truth``
    (:class:`robot.tally.SortingCounts`).

    Raises
    ------
    ValueError
        If a file is malformed, or the tally's onions are not the truth's (a tally from
        another line-up).
    """
    from recordings.labels.sorting_csv import read_tally, read_truth
    from robot.tally import count_fates

    rows = read_tally(config.tally)
    truth = read_truth(config.truth)
    held = {(r.lineup, r.index) for r in rows}
    if held != set(truth):
        missing, extra = set(truth) - held, held - set(truth)
        said = [f"it lacks {_onions(missing)}" if missing else "",
                f"it holds {_onions(extra)}" if extra else ""]
        raise ValueError(f"{config.tally} is not a tally of the onions {config.truth} names "
                         f"({'; '.join(s for s in said if s)}): a tally from another line-up?")
    return count_fates([truth[r.lineup, r.index] for r in rows], [r.fate for r in rows])
