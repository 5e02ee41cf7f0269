"""Calibration: measured confusion matrices -> the observation model the learners use.

Layouts: ``counts[true, predicted]``; ``C[true, predicted] = P(predicted | true)``.

Perception reports, for every unoccluded frame, an estimate of each state factor of the task
(:class:`irl.domains.task.TaskDescription`; for onion sorting the onion location, the
end-effector location and the prediction) and of the action. Run on
held-out labelled frames, those estimates give one confusion matrix per factor. Assuming the
errors of different factors are independent given the truth, their Kronecker product is the
state confusion, and with the action's confusion it is ``O[s, a, o]`` over pair observations
``o = s' * A + a'`` (:func:`irl.factored_observation_model`). The joint state confusion is kept
too, so the independence assumption can be checked against the data.

Frames the classifier calls occluded are not observations: they become ``None`` steps of the
demonstration and are not counted here.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from irl.domains.onion_sorting import SORTING_TASK
from irl.domains.task import TaskDescription
from irl.observation import ObservationModel, factored_observation_model

__all__ = [
    "FACTORS",
    "Calibration",
    "ConfusionMatrix",
    "calibrate",
    "calibration_factors",
    "confusion_counts",
    "load_calibration",
]

FORMAT = "onionsort.calibration/1"
_NO_SWAPS = ("this calibration does not say how often a whole session's reads of the onion's "
             "class were backwards (it predates the measure); calibrate again")


def calibration_factors(task: TaskDescription) -> dict[str, list[str]]:
    """The calibrated factors of ``task``: each state factor's value names, in the order of
    the state encoding, then ``"action"`` with the action names."""
    if not isinstance(task, TaskDescription):
        raise TypeError(f"task must be a TaskDescription; got {type(task).__name__}")
    if "action" in task.factors:
        raise ValueError(f"task {task.name!r} has a state factor named 'action', which the "
                         "action's confusion would shadow; rename it")
    return {**{f: list(v) for f, v in task.factors.items()}, "action": list(task.action_names)}


#: The calibrated factors of the onion-sorting task (:func:`calibration_factors`).
FACTORS: dict[str, list[str]] = calibration_factors(SORTING_TASK)


@dataclass(frozen=True)
class ConfusionMatrix:
    """Counts of (true, predicted) outcomes of one factor.

    Attributes
    ----------
    counts : ndarray of int, shape (n, n)
        ``counts[i, j]``: frames whose true value is i and predicted value is j.
    labels : list of str
    """

    counts: np.ndarray
    labels: list[str]

    def __post_init__(self) -> None:
        counts = np.asarray(self.counts)
        n = len(self.labels)
        if counts.shape != (n, n):
            raise ValueError(
                f"counts must have shape ({n}, {n}) for {n} labels; got {counts.shape}"
            )
        if np.any(counts < 0):
            raise ValueError("counts must be non-negative")
        object.__setattr__(self, "counts", counts.astype(np.int64))

    def probabilities(self, smoothing: float = 1.0) -> np.ndarray:
        """``C[true, predicted]`` with additive smoothing ``smoothing`` per cell.

        Smoothing keeps every confusion possible (no observation becomes impossible because it
        was never seen in calibration); rows without any data become uniform.
        """
        if smoothing < 0:
            raise ValueError(f"smoothing must be >= 0; got {smoothing}")
        c = self.counts + float(smoothing)
        rows = c.sum(axis=1, keepdims=True)
        empty = rows[:, 0] == 0
        c[empty] = 1.0
        return c / c.sum(axis=1, keepdims=True)

    @property
    def accuracy(self) -> float:
        """Fraction of frames predicted correctly (NaN without data)."""
        total = self.counts.sum()
        return float(np.trace(self.counts) / total) if total else float("nan")


def confusion_counts(true: np.ndarray, pred: np.ndarray, n: int, name: str) -> np.ndarray:
    true, pred = np.asarray(true, dtype=np.int64), np.asarray(pred, dtype=np.int64)
    if true.shape != pred.shape or true.ndim != 1:
        raise ValueError(
            f"{name}: true and predicted must be 1-D of equal length; got {true.shape} and "
            f"{pred.shape}"
        )
    for arr, which in ((true, "true"), (pred, "predicted")):
        if arr.size and (arr.min() < 0 or arr.max() >= n):
            raise ValueError(
                f"{name}: {which} values must lie in [0, {n}); got {arr.min()}..{arr.max()}"
            )
    counts = np.zeros((n, n), dtype=np.int64)
    np.add.at(counts, (true, pred), 1)
    return counts


@dataclass(frozen=True)
class Calibration:
    """Per-factor and joint confusion measured on held-out steps.

    Attributes
    ----------
    factors : dict of str -> ConfusionMatrix
        One per entry of :func:`calibration_factors` of ``task``.
    joint_state : ConfusionMatrix
        The confusion of the whole state (S x S; 48 x 48 for onion sorting).
    pair_correct : int
        Steps whose state and action were both right.
    smoothing : float
        Additive smoothing applied when the observation model is built.
    models : dict or None
        Which perception models were measured (their hashes), as read from the file.
    depth : bool or None
        Whether the classifier was given depth (RGB-D) or colour alone; a calibration holds
        only for the mode it was measured in. None in files that predate the field.
    inspection : bool or None
        Whether the inspection view was given (the prediction factor comes from it); a session
        without one (an imported video) needs a calibration measured without it.
    task : TaskDescription
        The task measured: its factors, in the order of the state encoding, and its sizes
        (the onion-sorting task by default).
    session_swaps : dict or None
        ``{"sessions": n, "swapped": k, "prediction_counts": counts}``: of the held-out
        sessions with enough reads of the onion's class, how many were read backwards in most
        of them, and the prediction factor's counts with those sessions' class reads swapped
        back (:func:`onionsort.stages.calibrate.session_swaps`); None in files that predate
        it.
    """

    factors: dict[str, ConfusionMatrix]
    joint_state: ConfusionMatrix
    pair_correct: int = 0
    smoothing: float = 1.0
    models: dict | None = None
    depth: bool | None = None
    inspection: bool | None = None
    task: TaskDescription = SORTING_TASK
    session_swaps: dict | None = None

    def __post_init__(self) -> None:
        if self.session_swaps is not None:
            swaps = self.session_swaps
            n, k = swaps.get("sessions"), swaps.get("swapped")
            if not all(isinstance(v, int) and not isinstance(v, bool) for v in (n, k)) \
                    or not 0 <= k <= n:
                raise ValueError(f"session_swaps must hold integers 0 <= swapped <= sessions; "
                                 f"got sessions {n!r}, swapped {k!r}")
            size = len(self.task.factors["prediction"])
            counts = np.asarray(swaps.get("prediction_counts"), dtype=object)
            if counts.shape != (size, size) or not all(
                    isinstance(v, int | np.integer) and not isinstance(v, bool) and v >= 0
                    for v in counts.ravel()):
                raise ValueError(f"session_swaps.prediction_counts must be a {size} x {size} "
                                 f"table of counts; got {swaps.get('prediction_counts')!r}")
            object.__setattr__(self, "session_swaps", {
                **swaps, "prediction_counts": counts.astype(np.int64).tolist()})
        expected = calibration_factors(self.task)
        if set(self.factors) != set(expected):
            raise ValueError(f"factors must be {list(expected)} (task {self.task.name!r}); "
                             f"got {sorted(self.factors)}")
        for k, labels in expected.items():
            if len(self.factors[k].labels) != len(labels):
                raise ValueError(f"factor {k!r} must have {len(labels)} values {labels} "
                                 f"(task {self.task.name!r}); got {self.factors[k].labels}")
        n = self.task.n_states
        if self.joint_state.counts.shape != (n, n):
            raise ValueError(f"joint_state must be {n} x {n} (task {self.task.name!r}); got "
                             f"{self.joint_state.counts.shape}")

    @property
    def task_name(self) -> str:
        """The name of the task measured."""
        return self.task.name

    @property
    def n_states(self) -> int:
        return self.task.n_states

    @property
    def n_actions(self) -> int:
        return self.task.n_actions

    def with_smoothing(self, smoothing: float) -> Calibration:
        """The same counts with another smoothing."""
        if smoothing < 0:
            raise ValueError(f"smoothing must be >= 0; got {smoothing}")
        return replace(self, smoothing=float(smoothing))

    def observation_model(self, smoothing: float | None = None, *,
                          within_sessions: bool = False) -> ObservationModel:
        """The learners' ``O[s, a, o]`` (S states x A actions, pair observations
        ``o = task.pair(s', a')``). ``within_sessions``: the prediction factor's confusion
        within a session given how it was read, the swapped sessions' reads swapped back
        (for a learner given :meth:`session_swap`, which models those sessions itself)."""
        smoothing = self.smoothing if smoothing is None else smoothing
        factors = dict(self.factors)
        if within_sessions:
            if self.session_swaps is None:
                raise ValueError(_NO_SWAPS)
            factors["prediction"] = ConfusionMatrix(
                np.array(self.session_swaps["prediction_counts"]),
                self.factors["prediction"].labels)
        mats = [factors[name].probabilities(smoothing) for name in self.task.factor_names]
        return factored_observation_model(mats, factors["action"].probabilities(smoothing))

    @property
    def session_swap_rate(self) -> float | None:
        """The probability that a session's class reads are backwards (more than half of
        them, as calibrate counts a swapped session): Laplace's rule of succession on the
        held-out sessions, ``(swapped + 1) / (sessions + 2)`` (never 0, so a learner given it
        can always doubt a session). None when not measured."""
        if self.session_swaps is None:
            return None
        return (self.session_swaps["swapped"] + 1) / (self.session_swaps["sessions"] + 2)

    def session_swap(self):
        """The learners' :class:`irl.observation.swap.SessionSwap`: the onion's class
        (``prediction`` good and bad) read backwards for a whole demonstration, at
        :attr:`session_swap_rate`. A ``ValueError`` when the calibration did not measure it."""
        from irl.observation.swap import value_swap

        if self.session_swaps is None:
            raise ValueError(_NO_SWAPS)
        return value_swap(self.task, "prediction", ("good", "bad"), self.session_swap_rate)

    @property
    def n_observed(self) -> int:
        """Steps counted (those perception did not call occluded)."""
        return int(self.joint_state.counts.sum())

    @property
    def state_error_rate(self) -> float:
        """Measured fraction of steps whose whole state estimate is wrong (the paper's ~30%)."""
        return 1.0 - self.joint_state.accuracy

    @property
    def pair_error_rate(self) -> float:
        """Measured fraction of steps whose state or action estimate is wrong."""
        return 1.0 - self.pair_correct / self.n_observed if self.n_observed else float("nan")

    @property
    def independent_state_error_rate(self) -> float:
        """The state error rate the factored observation model implies: each step's true state
        read right with the product of its factors' measured accuracies on their true values
        (no smoothing), weighted as the steps were. It equals :attr:`state_error_rate` when
        the factors' errors are independent given the truth, as the model assumes; a measured
        rate below it means errors come together."""
        n_s = self.joint_state.counts.sum(axis=1)
        if not n_s.sum():
            return float("nan")
        values = self.task.decode_array(np.arange(self.n_states))
        right = np.ones(self.n_states)
        for f, name in enumerate(self.task.factor_names):
            counts = self.factors[name].counts
            rows = counts.sum(axis=1)
            hit = np.divide(np.diag(counts), rows, out=np.ones(len(rows)), where=rows > 0)
            right *= hit[values[:, f]]
        return float(1.0 - (n_s * right).sum() / n_s.sum())

    @property
    def independent_pair_error_rate(self) -> float:
        """The (state, action) error rate if the action's errors were independent of the
        state's, as the factored observation model assumes: ``1 - (1 - state error rate) x
        action accuracy``, both measured. Compare :attr:`pair_error_rate`."""
        return 1.0 - (1.0 - self.state_error_rate) * self.factors["action"].accuracy

    def save(self, path: Path | str, extra: dict | None = None) -> Path:
        """Write the counts and the smoothing (applied when the model is built) as JSON.

        ``extra`` adds provenance (dataset, models, metrics). Written to a temporary file and
        renamed, so an existing file is never half-written.
        """
        path = Path(path)
        doc = {**(extra or {}),
            "format": FORMAT,
            "n_states": self.task.n_states,
            "n_actions": self.task.n_actions,
            "factors": {k: {"labels": m.labels, "counts": m.counts.tolist()}
                        for k, m in self.factors.items()},
            "joint_state_counts": self.joint_state.counts.tolist(),
            "pair_correct": self.pair_correct,
            "smoothing": self.smoothing,
            "state_error_rate": self.state_error_rate,
            "pair_error_rate": self.pair_error_rate,
            "accuracy": {k: m.accuracy for k, m in self.factors.items()},
            **({} if self.session_swaps is None else {"session_swaps": self.session_swaps}),
        }
        tmp = path.with_name(path.name + ".partial")
        tmp.write_text(json.dumps(doc, indent=1))
        tmp.replace(path)
        return path


def calibrate(true: dict[str, Sequence[int]], predicted: dict[str, Sequence[int]], *,
              task: TaskDescription = SORTING_TASK) -> Calibration:
    """Confusion matrices from true and predicted factor values of unoccluded frames.

    Parameters
    ----------
    true, predicted : dict of str -> sequence of int
        One entry per factor of :func:`calibration_factors` of ``task`` (for onion sorting,
        :data:`FACTORS`: ``onion``, ``end_effector``, ``prediction``, ``action``), each of
        length n_frames, value indices in the task's encoding.
    task : TaskDescription
        The task measured; the onion-sorting task by default.
    """
    expected = calibration_factors(task)
    missing = [k for k in expected if k not in true or k not in predicted]
    if missing:
        raise ValueError(f"true and predicted must both give the factors {list(expected)}; "
                         f"missing {missing}")
    factors = {k: ConfusionMatrix(confusion_counts(true[k], predicted[k], len(labels), k), labels)
               for k, labels in expected.items()}
    state_true = task.encode_array(
        np.stack([np.asarray(true[k], dtype=np.int64) for k in task.factor_names], axis=-1))
    state_pred = task.encode_array(
        np.stack([np.asarray(predicted[k], dtype=np.int64) for k in task.factor_names], axis=-1))
    joint = ConfusionMatrix(confusion_counts(state_true, state_pred, task.n_states, "state"),
                            [str(s) for s in range(task.n_states)])
    pair_correct = int(np.sum((state_true == state_pred)
                              & (np.asarray(true["action"]) == np.asarray(predicted["action"]))))
    return Calibration(factors=factors, joint_state=joint, pair_correct=pair_correct, task=task)


def load_calibration(path: Path | str, *, task: TaskDescription = SORTING_TASK) -> Calibration:
    """Read a calibration written by :meth:`Calibration.save` for ``task`` (the onion-sorting
    task by default); clear errors on bad files."""
    expected = calibration_factors(task)
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        raise FileNotFoundError(f"calibration file {path} does not exist") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path} is not a calibration file (not JSON: {exc})") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise ValueError(f"{path} is not a calibration file (format must be {FORMAT!r})")
    sizes = (task.n_states, task.n_actions)
    if (doc.get("n_states"), doc.get("n_actions")) != sizes:
        raise ValueError(
            f"{path} was calibrated for an MDP with (S, A) = ({doc.get('n_states')}, "
            f"{doc.get('n_actions')}), not the {task.name} MDP's {sizes}"
        )
    try:
        factors = {k: ConfusionMatrix(np.array(v["counts"]), list(v["labels"]))
                   for k, v in doc["factors"].items()}
        joint_counts = np.array(doc["joint_state_counts"])
    except (KeyError, TypeError, AttributeError) as exc:
        raise ValueError(f"{path} is not a calibration file (its counts are missing or "
                         f"malformed: {type(exc).__name__} {exc})") from None
    if set(factors) != set(expected):
        raise ValueError(f"{path}: factors must be {list(expected)}; got {sorted(factors)}")
    for k, labels in expected.items():
        if factors[k].labels != labels:
            raise ValueError(f"{path}: the values of factor {k!r} must be {labels} (task "
                             f"{task.name!r}); got {factors[k].labels}")
    joint = ConfusionMatrix(joint_counts, [str(s) for s in range(task.n_states)])
    depth, inspection = doc.get("depth"), doc.get("inspection")
    swaps = doc.get("session_swaps")
    if swaps is not None and not isinstance(swaps, dict):
        raise ValueError(f"{path}: session_swaps must be an object; got {swaps!r}")
    try:
        return Calibration(session_swaps=swaps, factors=factors, joint_state=joint,
                           pair_correct=int(doc.get("pair_correct", 0)),
                           smoothing=float(doc.get("smoothing", 1.0)), models=doc.get("models"),
                           depth=None if depth is None else bool(depth),
                           inspection=None if inspection is None else bool(inspection),
                           task=task)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
