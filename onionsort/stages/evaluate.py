"""Stage ``evaluate``: the Sawyer executes a learned policy; count how well it sorts.

Loads the greedy policy of a learning run (``RUN/model.json``) and lets the Sawyer sort a line-up
of onions in PyBullet: every abstract action is a real motion (IK, suction grasp), and the
onion's class at inspection comes from the detector on the inspection view, so perception
errors count. Reports TP (blemished in bin), FP (good in bin), TN (good left on the line), FN
(blemished left on the line), precision and recall into ``RUN/evaluation.json``, with a Rerun
recording of the sort (``RUN/evaluation.rrd``).

Example::

    from onionsort.stages import EvaluateConfig, evaluate
    result, summary = evaluate(EvaluateConfig(run=Path("runs/learn-mmap")))
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

from onionsort.stages.base import (
    check_difficulty,
    check_output_folder,
    log_config,
    write_json,
)
from onionsort.stages.learn import load_policy

__all__ = ["EvaluateConfig", "evaluate", "inspection_classifier"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class EvaluateConfig:
    """Which run to evaluate, on how many onions.

    Attributes
    ----------
    run : Path
        A folder written by ``learn``.
    onions, blemished : int
        Onions on the line, and how many of them are blemished.
    seed : int
    models : Path or None
        Perception models folder (None: the shipped models).
    ground_truth_inspection : bool
        Perfect inspection instead of the detector (for comparison).
    rerun : bool
        Write ``evaluation.rrd``.
    difficulty : str
        Perception difficulty, a level of ``robot.difficulty.DIFFICULTY_LEVELS`` (``clean``:
        today's station).
    """

    run: Path
    onions: int = 50
    blemished: int = 30
    seed: int = 0
    models: Path | None = None
    ground_truth_inspection: bool = False
    rerun: bool = True
    difficulty: str = "clean"

    def __post_init__(self) -> None:
        check_difficulty(self.difficulty)
        if self.onions < 1:
            raise ValueError(f"onions must be >= 1; got {self.onions}")
        if not 0 <= self.blemished <= self.onions:
            raise ValueError(f"blemished must be in [0, onions={self.onions}]; got "
                             f"{self.blemished}")


def inspection_classifier(detector):
    """``classify(rgb) -> prediction`` from the detector's best box in the inspection view: the
    index of ``bad`` (class 1, blemished), ``good`` or ``unknown`` (no onion found) among the
    values of the sorting task's ``prediction`` factor (``robot.station`` reads it as a
    ``Prediction``)."""
    from irl.domains.onion_sorting import SORTING_TASK
    from state_abstraction.perceive import inspected_class

    good, bad, unknown = (SORTING_TASK.value_index("prediction", v)
                          for v in ("good", "bad", "unknown"))

    def classify(rgb):
        cls = inspected_class(detector.detect([rgb])[0])
        return unknown if cls is None else (bad if cls == 1 else good)

    return classify


def evaluate(config: EvaluateConfig, models=None):
    """Evaluate a run's policy; write ``evaluation.json`` (and ``.rrd``).

    ``models`` (:class:`~onionsort.stages.models.PerceptionModels`) are used instead of loading
    ``config.models`` again, as ``demo`` does for its many evaluations.

    Returns ``(result, summary)``: the :class:`robot.evaluation.EvaluationResult` and the dict
    written to ``evaluation.json``.
    """
    log_config("evaluate", config)
    actions, doc = load_policy(config.run)
    check_output_folder(config.run, "RUN_DIR")  # it takes evaluation.json: writable?

    import torch

    from onionsort.stages.models import PerceptionModels
    from robot.evaluation import evaluate_policy

    torch.set_num_threads(2)
    detector = None
    if config.ground_truth_inspection:
        classify = "ground-truth"
    else:
        loaded = PerceptionModels.load(config.models) if models is None else models
        detector = loaded.detector
        classify = inspection_classifier(detector)
    logger_ = None
    if config.rerun:
        from recordings.rerun import EvaluationLogger
        from robot.camera import CameraSpec, intrinsics

        logger_ = EvaluationLogger(Path(config.run) / "evaluation.rrd", detector=detector,
                                   camera_K=intrinsics(CameraSpec()))
    try:
        result = evaluate_policy(actions, n_onions=config.onions, n_blemished=config.blemished,
                                 seed=config.seed, classify=classify, render=config.rerun,
                                 difficulty=config.difficulty,
                                 on_step=None if logger_ is None else logger_.on_step)
    finally:
        if logger_ is not None:
            logger_.close()
    summary = {"method": doc.get("method"), "seed": config.seed,
               "difficulty": config.difficulty, "inspection":
               "ground truth" if config.ground_truth_inspection else "detector",
               **result.to_dict()}
    write_json(Path(config.run) / "evaluation.json", summary)
    return result, summary
