"""Perception of a session, step by step: the observations the learners see.

Layouts: per-step probabilities ``probs[head][t, n_classes]``; observations are pair indices
``o = s * A + a`` of the onion-sorting MDP (the layout of
:func:`irl.pair_observation_model`), None where the classifier said occluded.

For each step the state classifier reads the onion and end-effector locations, the action, whether
a claimed onion waits at the gate, and whether the camera was occluded
(:mod:`state_abstraction.classifier`). The third state factor, the sorter's prediction, is not in
the main camera's picture: it is what the sorter learned by looking at the onion. It comes from
the inspection views of the step's frames: an inspection model (:class:`InspectionReader`, for
instance ``perception.Inspector``) gives each view the probability that the onion in it is
blemished, and the views of the onion in focus are fused as they come, the memory starting over
when a new onion is taken up (:func:`track_predictions`). The inspection view is a separate
camera that the passer-by does not block, so an inspection is seen even during an occluded step.

The inspection model is passed in, so this package does not depend on the detector's or the
inspection classifier's.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from irl.domains.onion_sorting import SORTING_TASK, Location, Prediction
from state_abstraction.classifier import (
    FACTOR_HEADS,
    OCCLUDED_THRESHOLD,
    StateClassifier,
    step_input,
)

__all__ = [
    "OCCLUDED_THRESHOLD",
    "PREDICTION_THRESHOLD",
    "InspectionReader",
    "PerceivedStep",
    "perceive_steps",
    "track_predictions",
]

logger = logging.getLogger(__name__)

PREDICTION_THRESHOLD = 0.5
"""The sorter is taken to have seen a blemish when the fused probability reaches this: the most
likely class (the learner's observation, not a decision with costs)."""
# OCCLUDED_THRESHOLD (imported above, defined in the classifier so that its evaluation uses the
# same call): a step is called occluded when ``P(occluded) >= OCCLUDED_THRESHOLD``, 0.2. Below
# 0.5 on purpose: a missed occlusion feeds the learner a garbage observation, a false alarm
# only drops one (MMAP-BIRL marginalizes it).


class InspectionReader(Protocol):
    """What perception needs of an inspection model."""

    def view_probabilities(self, views: list[np.ndarray]) -> list[float | None]:
        """Per view (H, W, 3) uint8: the probability that its onion is blemished, None where
        no onion is seen."""
        ...

    def fuse(self, view_p: Sequence[float]) -> float:
        """One probability from those of several views of one onion."""
        ...


@dataclass(frozen=True)
class PerceivedStep:
    """What perception reports for one step.

    Attributes
    ----------
    step : int
    occluded : bool
        The classifier's call (``p_occluded >= OCCLUDED_THRESHOLD``).
    p_occluded : float
    probs : dict of str -> ndarray
        Class probabilities of each classifier head.
    onion, end_effector, action, prediction : int
        The estimates (argmax; the prediction from :func:`track_predictions`).
    inspected : int or None
        The call (0 good, 1 blemished) on the onion seen in the inspection views of this
        step's frames, fused, None if none showed one.
    p_blemished : float or None
        The fused probability, over every view of the onion in focus seen so far, that it is
        blemished: what ``prediction`` is called from (None while none was seen).
    """

    step: int
    occluded: bool
    p_occluded: float
    probs: dict[str, np.ndarray] = field(repr=False)
    onion: int
    end_effector: int
    action: int
    prediction: int
    inspected: int | None = None
    p_blemished: float | None = None

    @property
    def state(self) -> int:
        """The perceived state's index."""
        return SORTING_TASK.encode({"onion": self.onion, "end_effector": self.end_effector,
                                    "prediction": self.prediction})

    @property
    def observation(self) -> int | None:
        """The pair observation ``s * A + a``, or None if the step was called occluded."""
        return None if self.occluded else SORTING_TASK.pair(self.state, self.action)

    def to_dict(self) -> dict:
        """A JSON-ready dict (the ``/perception/state`` message of a session)."""
        return {
            "step": self.step, "occluded": self.occluded, "p_occluded": self.p_occluded,
            "onion": self.onion, "end_effector": self.end_effector, "action": self.action,
            "prediction": self.prediction, "inspected": self.inspected,
            "p_blemished": None if self.p_blemished is None else round(self.p_blemished, 5),
            "state": self.state,
            "observation": self.observation,
            "probs": {k: [round(float(v), 5) for v in p] for k, p in self.probs.items()},
        }


def _mean(p: Sequence[float]) -> float:
    """The default fusion of several views' probabilities: their mean."""
    return float(np.mean(p))


def track_predictions(onion: Sequence[int], waiting: Sequence[bool],
                      occluded: Sequence[bool], at_rest: Sequence[Sequence[float]],
                      later: Sequence[Sequence[float]] | None = None,
                      fuse: Callable[[Sequence[float]], float] | None = None,
                      ) -> tuple[list[int], list[float | None]]:
    """The prediction factor of each step, from the views of the onion in focus seen so far.

    The memory starts over (UNKNOWN) when a new onion is taken up: a claimed onion waits at the
    gate, or the onion is just picked (HOVER). A view of the step's first frame (the state at
    rest) counts from that step on; a view of a later frame of the step, from the next step on
    (the step's state is the one at its start). Occluded steps keep the memory but still read
    the inspection views.

    Parameters
    ----------
    onion : sequence of int, length T
        Perceived onion location per step (ignored where occluded).
    waiting, occluded : sequence of bool, length T
    at_rest, later : sequence of sequences of float, length T
        Per step, the probabilities that the onion is blemished from its first frame's
        inspection view and from its later frames' (empty where no onion was seen; ``later``
        None: no later views).
    fuse : callable, optional
        ``fuse(probabilities) -> probability`` of the views of one onion (default: the mean).

    Returns
    -------
    predictions : list of int, length T
        :class:`~irl.domains.onion_sorting.Prediction` values: BAD where the fused probability
        reaches :data:`PREDICTION_THRESHOLD`.
    p_blemished : list of (float or None), length T
        The fused probability behind each (None while no view was seen).
    """
    n = len(onion)
    later = [()] * n if later is None else later
    if not (len(waiting) == len(occluded) == len(at_rest) == len(later) == n):
        raise ValueError(f"onion, waiting, occluded, at_rest and later must have equal lengths; "
                         f"got {n}, {len(waiting)}, {len(occluded)}, {len(at_rest)}, "
                         f"{len(later)}")
    fuse = _mean if fuse is None else fuse
    seen: list[float] = []
    predictions, probabilities = [], []
    for t in range(n):
        if not occluded[t] and (waiting[t] or onion[t] == Location.HOVER):
            seen = []
        seen.extend(at_rest[t])
        p_bad = fuse(seen) if seen else None
        predictions.append(int(Prediction.UNKNOWN if p_bad is None else
                               Prediction.BAD if p_bad >= PREDICTION_THRESHOLD
                               else Prediction.GOOD))
        probabilities.append(p_bad)
        seen.extend(later[t])
    return predictions, probabilities


def perceive_steps(
    classifier: StateClassifier,
    steps: Sequence[tuple[Sequence[np.ndarray], Sequence[np.ndarray | None] | None,
                          Sequence[np.ndarray | None] | np.ndarray | None]],
    inspection: InspectionReader | None,
    *, first_step: int = 0,
) -> list[PerceivedStep]:
    """Perceive consecutive steps of one session.

    Parameters
    ----------
    classifier : StateClassifier
    steps : sequence of (colors, depths, views)
        Per step, in order: its frames' colour images (H, W, 3) uint8 RGB and depths (H, W)
        metres, in time order, and the inspection views of its frames (h, w, 3), in the same
        order, None for a frame without one (a single array: the first frame's only; None:
        no view). ``depths`` may be None, or hold None for a frame, where there is no depth
        (a plain video): the classifier then reads that depth channel as zeros
        (:func:`~state_abstraction.classifier.step_input`), as a model trained with
        ``depth_dropout > 0`` has learned to (a warning is logged for one trained without).
    inspection : InspectionReader or None
        Reads the inspection views; None treats every view as empty (every prediction stays
        UNKNOWN).
    first_step : int
        Index of the first step (steps are numbered consecutively).
    """
    if not steps:
        return []
    no_depth = sum(d is None or any(f is None for f in d) for _, d, _ in steps)
    if no_depth and classifier.config.depth_dropout == 0:
        logger.warning("%d of %d steps have no depth, but this state classifier was trained "
                       "without depth dropout: its estimates of them are unreliable",
                       no_depth, len(steps))
    x = np.stack([step_input(c, d, classifier.config) for c, d, _ in steps])
    probs = classifier.predict(x)
    # every inspection view, as (step, frame within it, image)
    views = []
    for t, (_, _, v) in enumerate(steps):
        frames = [v] if isinstance(v, np.ndarray) else ([] if v is None else list(v))
        views.extend((t, k, img) for k, img in enumerate(frames) if img is not None)
    at_rest: list[list[float]] = [[] for _ in steps]
    later: list[list[float]] = [[] for _ in steps]
    if inspection is not None and views:
        for (t, k, _), p in zip(views, inspection.view_probabilities([img for *_, img in views]),
                                strict=True):
            if p is not None:
                (at_rest if k == 0 else later)[t].append(float(p))
    fuse = _mean if inspection is None else inspection.fuse
    best = {k: probs[k].argmax(axis=1) for k in FACTOR_HEADS}
    occluded = probs["occluded"][:, 1] >= OCCLUDED_THRESHOLD
    predictions, p_bad = track_predictions(best["onion"], best["waiting"] == 1, occluded,
                                           at_rest, later, fuse)
    inspected = [None if not (a or b) else
                 int(fuse(a + b) >= PREDICTION_THRESHOLD)
                 for a, b in zip(at_rest, later, strict=True)]
    return [
        PerceivedStep(
            step=first_step + t, occluded=bool(occluded[t]),
            p_occluded=float(probs["occluded"][t, 1]),
            probs={k: probs[k][t] for k in probs},
            onion=int(best["onion"][t]), end_effector=int(best["end_effector"][t]),
            action=int(best["action"][t]), prediction=predictions[t], inspected=inspected[t],
            p_blemished=p_bad[t],
        )
        for t in range(len(steps))
    ]
