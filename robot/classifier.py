"""What the Sawyer's inspection asks of a classifier, and how it reads the answer.

A classifier is passed in as a callable (``robot`` never imports perception): ``classify(views)``
on the held onion's inspection views, each (h, w, 3) uint8 RGB in the order of
:func:`robot.inspection_poses.inspection_poses`, answers a
:class:`~irl.domains.onion_sorting.Prediction` or a :class:`Verdict`;
:data:`GROUND_TRUTH` stands for perfect perception.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Literal, Protocol, runtime_checkable

import numpy as np

from irl.domains.onion_sorting import Prediction

__all__ = ["GROUND_TRUTH", "Classifier", "SequentialClassifier", "Verdict", "check_classifier",
           "read_answer"]


class Verdict(Protocol):
    """What a classifier may answer instead of a bare :class:`Prediction`: the class, with the
    probability behind it (``perception.InspectionVerdict`` is one)."""

    @property
    def prediction(self) -> int: ...

    @property
    def p_blemished(self) -> float | None: ...

    @property
    def view_p_blemished(self) -> tuple[float | None, ...]: ...


Classifier = Callable[[list[np.ndarray]], "Prediction | Verdict"]
"""``classify(views) -> Prediction or Verdict``: the held onion's class from all its inspection
views (each (h, w, 3) uint8 RGB, in the order of
:func:`~robot.inspection_poses.inspection_poses`): GOOD or BAD, or UNKNOWN to abstain (no view
shows an onion)."""


@runtime_checkable
class SequentialClassifier(Protocol):
    """A :data:`Classifier` that reads the views one at a time, so that the robot can stop
    showing an onion once its call is settled (``perception.Inspector`` is one).

    ``view_probabilities(views)`` gives each view's probability (None where it shows no
    onion); ``settled(view_p, remaining)`` whether ``remaining`` more views could still change
    the call on those; ``verdict(view_p)`` the call.
    """

    def __call__(self, views: list[np.ndarray]) -> Verdict: ...

    def view_probabilities(self, views: list[np.ndarray]) -> list[float | None]: ...

    def settled(self, view_p: list[float | None], remaining: int) -> bool: ...

    def verdict(self, view_p: list[float | None]) -> Verdict: ...


GROUND_TRUTH: Literal["ground-truth"] = "ground-truth"
"""Pass as ``classify`` to perceive every inspected onion's true class (perfect perception)."""


def check_classifier(classify: Classifier | Literal["ground-truth"]) -> None:
    """Raise unless ``classify`` is a callable or :data:`GROUND_TRUTH`.

    Raises
    ------
    ValueError
        If it is another string.
    TypeError
        If it is neither a string nor callable.
    """
    if isinstance(classify, str):
        if classify != GROUND_TRUTH:
            raise ValueError(f"classify must be a callable views -> Prediction or "
                             f"{GROUND_TRUTH!r}; got {classify!r}")
    elif not callable(classify):
        raise TypeError(f"classify must be a callable views -> Prediction or "
                        f"{GROUND_TRUTH!r}; got {type(classify).__name__}")


def read_answer(classify: Classifier | Literal["ground-truth"], blemished: bool,
                views: list[np.ndarray], view_p: list[float | None] | None = None
                ) -> tuple[Prediction | None, float | None, tuple[float | None, ...]]:
    """``classify``'s answer on ``views`` (None if it abstains: UNKNOWN), with the probability
    that the onion is blemished and that of each view, where it gives them; from a
    :class:`SequentialClassifier`'s ``view_p`` (one per view) when given. :data:`GROUND_TRUTH`
    answers the onion's true class ``blemished``.

    Raises
    ------
    ValueError
        If the answer is neither a :class:`Prediction` nor a verdict with one.
    """
    if classify == GROUND_TRUTH:
        truth = Prediction.BAD if blemished else Prediction.GOOD
        return truth, float(blemished), ()
    raw = classify(views) if view_p is None else classify.verdict(view_p)
    p_bad, per_view = None, ()
    if hasattr(raw, "prediction"):
        p_bad = getattr(raw, "p_blemished", None)
        per_view = tuple(getattr(raw, "view_p_blemished", ()))
        raw = raw.prediction
    try:
        answer = Prediction(int(raw))
    except (TypeError, ValueError):
        raise ValueError(f"classify must return a Prediction (GOOD, BAD, or UNKNOWN to "
                         f"abstain) or a verdict with one; got {raw!r}") from None
    return (None if answer == Prediction.UNKNOWN else answer,
            None if p_bad is None else float(p_bad), per_view)
