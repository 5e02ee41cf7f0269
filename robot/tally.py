"""Counting a sorted line-up: each onion's fate, TP/FP/TN/FN, precision and recall with their
95% Wilson intervals.

Each onion of a line-up ends with a *fate*: ``"bin"`` if the robot placed it in the bin,
``"line"`` if it set it back on the line after inspecting it (it rides away), ``"tray"`` if it
deferred it to a person (counted apart, in ``deferred``); onions still undecided when an
episode ends count as left on the line. With blemished onions the positive class:

=====  ==============================  =====  ==============================
TP     blemished onion in the bin      FP     good onion in the bin
FN     blemished onion left on line    TN     good onion left on the line
=====  ==============================  =====  ==============================

``precision = TP / (TP + FP)`` and ``recall = TP / (TP + FN)``, over the onions the robot
sorted; a ratio with a zero denominator (nothing binned; no blemished onion) is 0.0, as
scikit-learn's ``zero_division=0``. Each comes with its 95% Wilson score interval
(:func:`wilson_interval`; ``[0, 1]`` where the denominator is zero).

:class:`SortingTally` is the one place where an episode is counted, action by action (the
sorting loop, :mod:`robot.cell`, feeds it); :func:`count_fates` counts fates read back from a
file (``onionsort score``). Neither imports the simulator.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from irl.domains.onion_sorting import Prediction

__all__ = ["FATES", "Fate", "OnionOutcome", "SortingCounts", "SortingResult", "SortingTally",
           "count_fates", "wilson_interval"]

logger = logging.getLogger(__name__)

Fate = Literal["bin", "line", "tray"]
#: The fates an onion may end with.
FATES: tuple[Fate, ...] = ("bin", "line", "tray")
#: The standard normal quantile of a two-sided 95% interval.
_Z95 = 1.959963984540054


def wilson_interval(successes: int, trials: int, z: float = _Z95) -> tuple[float, float]:
    """The Wilson score interval ``(low, high)`` of a proportion ``successes / trials``.

    With ``z`` the normal quantile (1.96 for 95%), the centre is ``(k + z^2 / 2) / (n + z^2)``
    and the half-width ``z sqrt(k (n - k) / n + z^2 / 4) / (n + z^2)`` (Wilson, 1927). It stays
    inside [0, 1] and keeps its coverage for small ``n`` and proportions near 0 or 1, where the
    normal approximation does not. ``trials == 0`` gives ``(0.0, 1.0)``: nothing is known.

    Raises
    ------
    ValueError
        If the counts are not integers with ``0 <= successes <= trials``.
    """
    for name, value in (("successes", successes), ("trials", trials)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer):
            raise ValueError(f"{name} must be an int; got {value!r}")
    if not 0 <= successes <= trials:
        raise ValueError(f"successes must be in [0, trials={trials}]; got {successes}")
    if trials == 0:
        return 0.0, 1.0
    k, n, z2 = float(successes), float(trials), z * z
    centre = (k + z2 / 2) / (n + z2)
    half = z * math.sqrt(k * (n - k) / n + z2 / 4) / (n + z2)
    # none or all succeeded: that edge is exact (the formula's rounding would miss it)
    low = 0.0 if successes == 0 else max(0.0, centre - half)
    high = 1.0 if successes == trials else min(1.0, centre + half)
    return low, high


def _ratio(num: int, den: int) -> float:
    return num / den if den else 0.0


class _PrecisionRecall:
    """``precision`` and ``recall``, with their intervals, of ``tp``, ``fp`` and ``fn``."""

    tp: int
    fp: int
    fn: int

    @property
    def precision(self) -> float:
        """``TP / (TP + FP)``; 0.0 while nothing is binned."""
        return _ratio(self.tp, self.tp + self.fp)

    @property
    def recall(self) -> float:
        """``TP / (TP + FN)``; 0.0 while no blemished onion is decided."""
        return _ratio(self.tp, self.tp + self.fn)

    @property
    def precision_ci(self) -> tuple[float, float]:
        """The 95% Wilson interval of :attr:`precision`."""
        return wilson_interval(self.tp, self.tp + self.fp)

    @property
    def recall_ci(self) -> tuple[float, float]:
        """The 95% Wilson interval of :attr:`recall`."""
        return wilson_interval(self.tp, self.tp + self.fn)


@dataclass(frozen=True)
class SortingCounts(_PrecisionRecall):
    """TP/FP/TN/FN of a sorted line-up (or several), and how many onions went to a person."""

    tp: int
    fp: int
    tn: int
    fn: int
    deferred: int = 0

    @property
    def n_onions(self) -> int:
        """Every onion counted, deferred ones too."""
        return self.tp + self.fp + self.tn + self.fn + self.deferred

    @property
    def deferral_rate(self) -> float:
        """The share of the onions deferred to a person."""
        return _ratio(self.deferred, self.n_onions)

    def to_dict(self) -> dict:
        """A JSON-ready dict: the counts, precision and recall with their 95% intervals, the
        deferred onions and their share."""
        return _summary(self)

    def table(self) -> str:
        """The confusion table with precision and recall, as aligned text."""
        return "\n".join(_table(self, f"({self.n_onions} onions)"))


def _summary(counts) -> dict:
    return {"tp": counts.tp, "fp": counts.fp, "tn": counts.tn, "fn": counts.fn,
            "precision": counts.precision, "recall": counts.recall,
            "precision_ci": list(counts.precision_ci), "recall_ci": list(counts.recall_ci),
            "deferred": counts.deferred, "deferral_rate": counts.deferral_rate}


def _table(counts, what: str) -> list[str]:
    (p_lo, p_hi), (r_lo, r_hi) = counts.precision_ci, counts.recall_ci
    rows = [
        f"{'':>15} {'in bin':>8} {'on line':>8}",
        f"{'blemished':>15} {'TP ' + str(counts.tp):>8} {'FN ' + str(counts.fn):>8}",
        f"{'good':>15} {'FP ' + str(counts.fp):>8} {'TN ' + str(counts.tn):>8}",
        f"precision {counts.precision:.3f} [{p_lo:.3f}, {p_hi:.3f}]   recall "
        f"{counts.recall:.3f} [{r_lo:.3f}, {r_hi:.3f}]   {what}",
    ]
    if counts.deferred:
        rows.append(f"deferred to a person: {counts.deferred} (rate "
                    f"{counts.deferral_rate:.3f}; not in the counts above)")
    return rows


@dataclass(frozen=True)
class OnionOutcome:
    """What happened to one onion of the line-up.

    Attributes
    ----------
    index : int
        Position in the line-up.
    blemished : bool or None
        Its true class (None where unknown: a lab's run scored afterwards).
    perceived : Prediction or None
        What the inspection called it (None if never inspected).
    fate : {"bin", "line", "tray"}
        Where it ended; undecided onions count as ``"line"``; ``"tray"`` if the robot deferred
        it to a person.
    decided : bool
        False if the episode ended before the robot released it for good (or claimed it).
    p_blemished : float or None
        The inspection's probability that it is blemished, where the classifier gave one.
    views : int
        Inspection views the robot took of it (0 if never inspected).
    """

    index: int
    blemished: bool | None
    perceived: Prediction | None
    fate: Fate
    decided: bool = True
    p_blemished: float | None = None
    views: int = 0

    def to_dict(self) -> dict:
        return {
            "index": self.index, "blemished": self.blemished,
            "perceived": None if self.perceived is None else self.perceived.name.lower(),
            "p_blemished": None if self.p_blemished is None else round(self.p_blemished, 5),
            "fate": self.fate, "decided": self.decided, "views": self.views,
        }


@dataclass(frozen=True)
class SortingResult(_PrecisionRecall):
    """The outcome of one evaluation episode (see the module docstring for the counts)."""

    tp: int
    fp: int
    tn: int
    fn: int
    n_steps: int
    undecided: int
    onions: tuple[OnionOutcome, ...] = field(repr=False)
    deferred: int = 0

    def __post_init__(self) -> None:
        if self.tp + self.fp + self.tn + self.fn + self.deferred != len(self.onions):
            raise ValueError(
                f"tp + fp + tn + fn + deferred must equal the number of onions "
                f"{len(self.onions)}; got {self.tp} + {self.fp} + {self.tn} + {self.fn} + "
                f"{self.deferred}"
            )

    @property
    def deferral_rate(self) -> float:
        """The share of the line-up deferred to a person."""
        return _ratio(self.deferred, len(self.onions))

    @property
    def counts(self) -> SortingCounts:
        """Its TP/FP/TN/FN and deferred onions."""
        return SortingCounts(self.tp, self.fp, self.tn, self.fn, self.deferred)

    def to_dict(self) -> dict:
        """A JSON-ready dict: counts, precision and recall with their 95% intervals, steps,
        the inspection views taken and the per-onion outcomes."""
        return {**_summary(self), "n_onions": len(self.onions), "n_steps": self.n_steps,
                "undecided": self.undecided, "views_taken": self.views_taken,
                "onions": [o.to_dict() for o in self.onions]}

    @property
    def views_taken(self) -> int:
        """Inspection views the robot took in all."""
        return sum(o.views for o in self.onions)

    def table(self) -> str:
        """The confusion table with precision and recall, as aligned text."""
        return "\n".join(_table(self, f"({len(self.onions)} onions, {self.n_steps} steps, "
                                      f"{self.undecided} undecided)"))


def _cell(blemished: bool, fate: Fate) -> str:
    if fate == "bin":
        return "tp" if blemished else "fp"
    return "fn" if blemished else "tn"


def count_fates(blemished: Sequence[bool], fates: Sequence[Fate]) -> SortingCounts:
    """TP/FP/TN/FN and the deferred onions of onions of classes ``blemished`` (n,) whose fates
    were ``fates`` (n,).

    Raises
    ------
    ValueError
        If the lengths differ or a fate is not one of :data:`FATES`.
    """
    if len(blemished) != len(fates):
        raise ValueError(f"blemished and fates must have one entry per onion; got "
                         f"{len(blemished)} and {len(fates)}")
    counts = {"tp": 0, "fp": 0, "tn": 0, "fn": 0, "deferred": 0}
    for bad, fate in zip(blemished, fates, strict=True):
        if fate not in FATES:
            raise ValueError(f"a fate must be one of {', '.join(FATES)}; got {fate!r}")
        counts["deferred" if fate == "tray" else _cell(bool(bad), fate)] += 1
    return SortingCounts(**counts)


class SortingTally:
    """The fates of a line-up's onions and what their inspections said, action by action.

    The one place where an episode is counted: the sorting loop (:class:`robot.cell.
    SortingRun`, which :func:`robot.evaluation.evaluate_policy` and the Gymnasium environment
    run) records every fate and inspection here.

    Parameters
    ----------
    n_onions : int
        The line-up's size.
    blemished : ndarray of shape (n_onions,), optional
        The line-up's true classes, where they are known (a simulated line-up; a recorded one
        with its truth): the running counts and :meth:`result` need them.

    Attributes
    ----------
    fates : list of {"bin", "line", "tray"} or None
        Each onion's fate so far (None while undecided).
    calls : dict
        The inspection's call on each inspected onion (a Prediction).
    p_blemished : dict
        The inspection's probability that each inspected onion is blemished, where it gave one.
    views : dict
        Inspection views taken of each inspected onion.
    counts : dict
        ``tp``, ``fp``, ``tn``, ``fn`` over the onions decided so far (zeros without
        ``blemished``).
    """

    def __init__(self, n_onions: int, blemished: np.ndarray | None = None) -> None:
        if isinstance(n_onions, bool) or not isinstance(n_onions, int | np.integer) \
                or n_onions < 1:
            raise ValueError(f"n_onions must be an int >= 1; got {n_onions!r}")
        self._blemished = None
        if blemished is not None:
            self._blemished = np.asarray(blemished, bool).copy()
            if self._blemished.shape != (n_onions,):
                raise ValueError(f"blemished must hold one class per onion, shape "
                                 f"({n_onions},); got shape {self._blemished.shape}")
        self.fates: list[Fate | None] = [None] * int(n_onions)
        self.calls: dict[int, Prediction] = {}
        self.p_blemished: dict[int, float] = {}
        self.views: dict[int, int] = {}
        self.counts = {"tp": 0, "fp": 0, "tn": 0, "fn": 0}

    @property
    def n_onions(self) -> int:
        """The line-up's size."""
        return len(self.fates)

    @property
    def knows_truth(self) -> bool:
        """Whether the line-up's true classes were given."""
        return self._blemished is not None

    def is_blemished(self, index: int) -> bool:
        """The true class of line-up onion ``index``.

        Raises
        ------
        ValueError
            If the tally was given no truth.
        """
        if self._blemished is None:
            raise ValueError("the line-up's true classes are unknown; give them (blemished) to "
                             "count TP/FP/TN/FN")
        return bool(self._blemished[index])

    @property
    def complete(self) -> bool:
        """Whether every onion has a fate (the episode is over)."""
        return all(f is not None for f in self.fates)

    def inspected(self, index: int, call: Prediction, p_blemished: float | None,
                  views: int) -> None:
        """Keep what the inspection of onion ``index`` said: its ``call``, its probability of
        a blemish (None where the classifier gave none), and the ``views`` it took."""
        self.calls[index] = call
        if p_blemished is not None:
            self.p_blemished[index] = float(p_blemished)
        self.views[index] = self.views.get(index, 0) + int(views)

    def decide(self, index: int, fate: Fate) -> bool:
        """Onion ``index`` ended with ``fate``; count it (a deferred one apart). Returns False
        (and changes nothing) if it had its fate already.

        Raises
        ------
        ValueError
            If ``fate`` is not one of :data:`FATES`.
        """
        if fate not in FATES:
            raise ValueError(f"a fate must be one of {', '.join(FATES)}; got {fate!r}")
        if self.fates[index] is not None:
            return False
        self.fates[index] = fate
        if fate != "tray" and self._blemished is not None:
            self.counts[_cell(self.is_blemished(index), fate)] += 1
        return True

    def outcomes(self) -> tuple[OnionOutcome, ...]:
        """What happened to each onion so far, in line-up order; an undecided onion counts as
        left on the line, and its class is None where the tally was given no truth."""
        return tuple(
            OnionOutcome(index=i, blemished=None if self._blemished is None
                         else self.is_blemished(i), perceived=self.calls.get(i),
                         fate=self.fates[i] or "line", decided=self.fates[i] is not None,
                         p_blemished=self.p_blemished.get(i), views=self.views.get(i, 0))
            for i in range(self.n_onions))

    def result(self, n_steps: int) -> SortingResult:
        """The episode's :class:`SortingResult` after ``n_steps`` actions; onions still
        undecided count as left on the line.

        Raises
        ------
        ValueError
            If the tally was given no truth.
        """
        if self._blemished is None:
            self.is_blemished(0)  # raises, naming what is missing
        n_onions = self.n_onions
        undecided = sum(f is None for f in self.fates)
        if undecided:
            logger.info("the episode ended after %d steps with %d of %d onions undecided (left "
                        "on the line)", n_steps, undecided, n_onions)
        outcomes = self.outcomes()
        counts = count_fates([o.blemished for o in outcomes], [o.fate for o in outcomes])
        result = SortingResult(tp=counts.tp, fp=counts.fp, tn=counts.tn, fn=counts.fn,
                               n_steps=n_steps, undecided=undecided, onions=outcomes,
                               deferred=counts.deferred)
        logger.info("sorted %d onions in %d steps: precision %.3f, recall %.3f", n_onions,
                    n_steps, result.precision, result.recall)
        return result
