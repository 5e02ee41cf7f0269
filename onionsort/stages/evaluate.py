"""Stage ``evaluate``: the Sawyer executes a learned policy; count how well it sorts.

Loads the greedy policy of a learning run (``RUN/model.json``) and lets the Sawyer sort a line-up
of onions in PyBullet: every abstract action is a real motion (IK, suction grasp), and the
onion's class at inspection comes from the detector on the inspection view, so perception
errors count. Reports TP (blemished in bin), FP (good in bin), TN (good left on the line), FN
(blemished left on the line), precision and recall into ``RUN/evaluation.json``, with a Rerun
recording of the sort (``RUN/evaluation.rrd``: the camera, the inspection views, the decisions,
the counts, and the work cell and the Sawyer in 3D) and the run as a session
(``RUN/evaluation.mcap``, :mod:`recordings`): one frame per action, showing the station at rest
before it (camera, depth, ground truth, ``/tf``, ``/joint_states``, ``/scene``), the inspection
view the classifier read, and each step's decision and running TP/FP/TN/FN
(``/evaluation/decision``, ``/evaluation/counts``). Both files are written under temporary
names and renamed once complete.

Example::

    from onionsort.stages import EvaluateConfig, evaluate
    result, summary = evaluate(EvaluateConfig(run=Path("runs/learn-mmap")))
"""

from __future__ import annotations

import contextlib
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

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
    mcap : bool
        Write ``evaluation.mcap``, the run as a session (Foxglove, ``rerun mcap convert``,
        :func:`recordings.open_session`).
    difficulty : str
        Perception difficulty, a level of ``robot.difficulty.DIFFICULTY_LEVELS`` (``clean``:
        today's station).
    connect : str or None
        Also stream the Rerun recording to a viewer at this gRPC URL
        (``rerun+http://HOST:PORT/proxy``).
    """

    run: Path
    onions: int = 50
    blemished: int = 30
    seed: int = 0
    models: Path | None = None
    ground_truth_inspection: bool = False
    rerun: bool = True
    difficulty: str = "clean"
    mcap: bool = True
    connect: str | None = None

    def __post_init__(self) -> None:
        check_difficulty(self.difficulty)
        if self.connect is not None:
            from recordings.rerun.common import check_viewer_url

            check_viewer_url(self.connect)
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


class _LastDetection:
    """The detector, remembering its answer on the last single image: the Rerun log draws the
    boxes of the inspection view the classifier has just read without running the detector on
    it again."""

    def __init__(self, detector) -> None:
        self.detector = detector
        self._image: Any = None
        self._found: Any = None

    def detect(self, images) -> list:
        import numpy as np

        if len(images) == 1 and self._image is not None \
                and np.array_equal(np.asarray(images[0]), self._image):
            return [self._found]
        found = self.detector.detect(images)
        if len(images) == 1:
            self._image, self._found = np.array(images[0], copy=True), found[0]
        return found


class _SessionRecorder:
    """Writes an evaluation's steps to a session: frame ``t`` (step ``t``, one frame a step)
    shows the station at rest before action ``t``, labelled with that action; it carries the
    inspection view the action's classifier read, and the action's decision and the counts
    after it. The view before action ``t + 1`` is the one after action ``t``."""

    def __init__(self, writer) -> None:
        self.writer = writer
        self._view: Any = None

    def on_start(self, view) -> None:
        self._view = view

    def on_step(self, event) -> None:
        from robot.labels import StepLabel
        from robot.world import WorldFrame

        view, t = self._view, int(event.step)
        if view is None:
            raise RuntimeError("the evaluation reported a step before its start")
        time_ns = round(view.time_s * 1e9)
        self.writer.write_decision(event, frame=t, time_ns=time_ns)
        self.writer.write_frame(WorldFrame(
            index=t, step=StepLabel(step=t, state=int(event.state), action=int(event.action),
                                    next_state=int(event.next_state), occluded=False),
            phase=0, time_s=view.time_s, color=view.color, depth=view.depth,
            onions=view.onions, inspection=event.inspection, world=view.world))
        self._view = event


def _session_metadata(config: EvaluateConfig, doc: dict, resolved: dict) -> dict:
    import platform

    import numpy as np
    import pybullet

    from onionsort import __version__

    return {"source": "onionsort evaluate", "seed": config.seed, "config": resolved,
            "method": doc.get("method"), "software": f"onionsort {__version__}",
            "versions": {"python": platform.python_version(), "numpy": np.__version__,
                         "pybullet_api": pybullet.getAPIVersion()},
            "policy": f"greedy policy of {Path(config.run) / 'model.json'}"}


def evaluate(config: EvaluateConfig, models=None):
    """Evaluate a run's policy; write ``evaluation.json`` (and ``.rrd``, ``.mcap``).

    ``models`` (:class:`~onionsort.stages.models.PerceptionModels`) are used instead of loading
    ``config.models`` again, as ``demo`` does for its many evaluations.

    Returns ``(result, summary)``: the :class:`robot.evaluation.EvaluationResult` and the dict
    written to ``evaluation.json``.
    """
    resolved = log_config("evaluate", config)
    actions, doc = load_policy(config.run)
    check_output_folder(config.run, "RUN_DIR")  # it takes evaluation.json: writable?
    if config.connect is not None:
        from recordings.rerun.common import reach_viewer

        reach_viewer(config.connect)

    import torch

    from onionsort.stages.models import PerceptionModels
    from robot.camera import CameraSpec, intrinsics
    from robot.evaluation import evaluate_policy
    from robot.station import station_robot
    from robot.world import camera_pose

    torch.set_num_threads(2)
    detector = None
    if config.ground_truth_inspection:
        classify = "ground-truth"
    else:
        loaded = PerceptionModels.load(config.models) if models is None else models
        detector = _LastDetection(loaded.detector)
        classify = inspection_classifier(detector)
    on_step, recorder = [], None
    session = Path(config.run) / "evaluation.mcap"
    partial = session.with_name(session.name + ".partial")
    try:
        with contextlib.ExitStack() as stack:
            logged = config.rerun or config.connect is not None
            if logged:
                from recordings.rerun import EvaluationLogger
                from recordings.rerun.common import rerun_targets

                on_step.append(stack.enter_context(EvaluationLogger(
                    rerun_targets(Path(config.run) / "evaluation.rrd" if config.rerun else None,
                                  config.connect), detector=detector,
                    camera_K=intrinsics(CameraSpec()), robot=station_robot(),
                    camera_pose=camera_pose(CameraSpec()))).on_step)
            if config.mcap:
                from recordings import SessionWriter
                from robot.simulation import INSPECTION_CAMERA

                recorder = _SessionRecorder(stack.enter_context(SessionWriter(
                    partial, _session_metadata(config, doc, resolved), intrinsics(CameraSpec()),
                    intrinsics(INSPECTION_CAMERA), frames_per_step=1, overwrite=True)))
                on_step.append(recorder.on_step)

            def each_step(event) -> None:
                for call in on_step:
                    call(event)

            result = evaluate_policy(
                actions, n_onions=config.onions, n_blemished=config.blemished,
                seed=config.seed, classify=classify, render=logged or config.mcap,
                difficulty=config.difficulty, on_step=each_step if on_step else None,
                on_start=None if recorder is None else recorder.on_start)
        if recorder is not None:
            partial.replace(session)
    finally:
        partial.unlink(missing_ok=True)  # a run that failed leaves no session behind
    summary = {"method": doc.get("method"), "seed": config.seed,
               "difficulty": config.difficulty, "inspection":
               "ground truth" if config.ground_truth_inspection else "detector",
               **result.to_dict()}
    write_json(Path(config.run) / "evaluation.json", summary)
    return result, summary
