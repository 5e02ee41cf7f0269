"""Perception of a session, step by step: the observations the learners see.

Layouts: per-step probabilities ``probs[head][t, n_classes]``; observations are pair indices
``o = s * A + a`` of the onion-sorting MDP (the layout of
:func:`irl.pair_observation_model`), None where the classifier said occluded.

For each step the state classifier reads the onion and end-effector locations, the action, whether
a claimed onion waits at the gate, and whether the camera was occluded
(:mod:`state_abstraction.classifier`). The third state factor, the sorter's prediction, is not in
the main camera's picture: it is what the sorter learned by looking at the onion. It comes from
the detector's class of the onion in the inspection view, remembered until a new onion is taken
up (:func:`track_predictions`). The inspection view is a separate camera that the passer-by does
not block, so an inspection is seen even during an occluded step.

The detector is passed in as a callable (``detect(images) -> detections``, each with ``classes``
and ``scores`` arrays, e.g. :meth:`perception.Detector.detect`), so this package does not depend
on the detector's.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

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
    "PerceivedStep",
    "inspected_class",
    "perceive_steps",
    "track_predictions",
]

logger = logging.getLogger(__name__)

#: Minimum detector score for an onion in the inspection view to count as seen.
INSPECTION_SCORE = 0.2
# OCCLUDED_THRESHOLD (imported above, defined in the classifier so that its evaluation uses the
# same call): a step is called occluded when ``P(occluded) >= OCCLUDED_THRESHOLD``, 0.2. Below
# 0.5 on purpose: a missed occlusion feeds the learner a garbage observation, a false alarm
# only drops one (MMAP-BIRL marginalizes it).


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
        The detector's class (0 good, 1 blemished) of an onion seen in the inspection view on
        this step, None if none was seen.
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
            "prediction": self.prediction, "inspected": self.inspected, "state": self.state,
            "observation": self.observation,
            "probs": {k: [round(float(v), 5) for v in p] for k, p in self.probs.items()},
        }


def track_predictions(onion: Sequence[int], waiting: Sequence[bool],
                      occluded: Sequence[bool], inspected: Sequence[int | None]) -> list[int]:
    """The prediction factor of each step, from what was seen so far.

    The memory is reset to UNKNOWN when a new onion is taken up: a claimed onion waits at the
    gate, or the onion is just picked (HOVER); it becomes the detector's class when the
    inspection view shows an onion. Occluded steps keep the memory but still read the
    inspection view.

    Parameters
    ----------
    onion : sequence of int, length T
        Perceived onion location per step (ignored where occluded).
    waiting, occluded : sequence of bool, length T
    inspected : sequence of (int or None), length T
        Detector class (0 good, 1 blemished) of an onion in the step's inspection view.

    Returns
    -------
    list of int, length T
        :class:`~irl.domains.onion_sorting.Prediction` values.
    """
    n = len(onion)
    if not (len(waiting) == len(occluded) == len(inspected) == n):
        raise ValueError(f"onion, waiting, occluded and inspected must have equal lengths; got "
                         f"{n}, {len(waiting)}, {len(occluded)}, {len(inspected)}")
    memory, out = Prediction.UNKNOWN, []
    for t in range(n):
        if not occluded[t] and (waiting[t] or onion[t] == Location.HOVER):
            memory = Prediction.UNKNOWN
        if inspected[t] is not None:
            memory = Prediction.BAD if inspected[t] == 1 else Prediction.GOOD
        out.append(int(memory))
    return out


def inspected_class(detections, min_score: float = INSPECTION_SCORE) -> int | None:
    """The class of the best-scoring detection at or above ``min_score``, else None."""
    scores = np.asarray(detections.scores)
    if scores.size == 0 or scores.max() < min_score:
        return None
    return int(np.asarray(detections.classes)[int(scores.argmax())])


def perceive_steps(
    classifier: StateClassifier,
    steps: Sequence[tuple[Sequence[np.ndarray], Sequence[np.ndarray | None] | None,
                          np.ndarray | None]],
    detect: Callable[[list[np.ndarray]], list] | None,
    *, first_step: int = 0,
) -> list[PerceivedStep]:
    """Perceive consecutive steps of one session.

    Parameters
    ----------
    classifier : StateClassifier
    steps : sequence of (colors, depths, inspection)
        Per step, in order: its frames' colour images (H, W, 3) uint8 RGB and depths (H, W)
        metres, in time order, and the inspection view (h, w, 3) of its first frame (or None).
        ``depths`` may be None, or hold None for a frame, where there is no depth (a plain
        video): the classifier then reads that depth channel as zeros
        (:func:`~state_abstraction.classifier.step_input`), as a model trained with
        ``depth_dropout > 0`` has learned to (a warning is logged for one trained without).
    detect : callable or None
        The detector, ``detect(list of images) -> list of detections``; None treats every
        inspection view as empty (every prediction stays UNKNOWN).
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
    views = [(t, v) for t, (_, _, v) in enumerate(steps) if v is not None]
    inspected: list[int | None] = [None] * len(steps)
    if detect is not None and views:
        for (t, _), det in zip(views, detect([v for _, v in views]), strict=True):
            inspected[t] = inspected_class(det)
    best = {k: probs[k].argmax(axis=1) for k in FACTOR_HEADS}
    occluded = probs["occluded"][:, 1] >= OCCLUDED_THRESHOLD
    predictions = track_predictions(best["onion"], best["waiting"] == 1, occluded, inspected)
    return [
        PerceivedStep(
            step=first_step + t, occluded=bool(occluded[t]),
            p_occluded=float(probs["occluded"][t, 1]),
            probs={k: probs[k][t] for k in probs},
            onion=int(best["onion"][t]), end_effector=int(best["end_effector"][t]),
            action=int(best["action"][t]), prediction=predictions[t], inspected=inspected[t],
        )
        for t in range(len(steps))
    ]
