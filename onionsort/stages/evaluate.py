"""Stage ``evaluate``: the Sawyer executes a policy; count how well it sorts.

Takes the greedy policy of a learning run (``RUN/model.json``) or the task's own (the expert's:
perception measured apart from learning) and lets the Sawyer sort a line-up of onions in
PyBullet: every abstract action is a real motion (IK, suction grasp). At inspection the Sawyer
shows each onion to its camera from several sides; the detector finds it in each view, the
inspection classifier reads it, the views are fused, and the onion is called blemished when the
fused probability reaches the threshold of two costs (a blemished onion left on the line, a good
one binned; by default the task's reward's). So perception errors count. Reports TP (blemished
in bin), FP (good in bin), TN (good left on the line), FN (blemished left on the line),
precision and recall with their 95% Wilson intervals into ``OUT/evaluation.json``, each
onion's fate, call and probability into ``OUT/tally.csv`` (``onionsort score`` counts it
against a truth), with a Rerun recording of the sort
(``OUT/evaluation.rrd``: the camera, the inspection views, the decisions, the counts, and the
work cell and the Sawyer in 3D) and the run as a session (``OUT/evaluation.mcap``,
:mod:`recordings`): one frame per action, showing the station at rest before it (camera,
depth, ground truth, ``/tf``, ``/joint_states``, ``/scene``), the first inspection view the
classifier read, and each step's decision (with the inspection's probabilities) and running
TP/FP/TN/FN (``/evaluation/decision``, ``/evaluation/counts``). ``OUT`` is the run folder
unless another is given. Both files are written under temporary names and renamed once
complete. ``record_lineup`` also records the line-up (:class:`onionsort.stages.lineup.
LineupRecorder`), and ``lineup`` replays the policy on a recorded one instead of the simulator
(:func:`onionsort.stages.lineup.evaluate_lineup`).

Example::

    from onionsort.stages import EvaluateConfig, evaluate
    result, summary = evaluate(EvaluateConfig(run=Path("runs/learn-mmap")))
    result, summary = evaluate(EvaluateConfig(policy="expert", out=Path("runs/eyes")))
"""

from __future__ import annotations

import contextlib
import logging
from pathlib import Path
from typing import Any

import numpy as np

from onionsort.configs.evaluate import POLICIES, EvaluateConfig
from onionsort.policy import load_confidence, load_policy
from onionsort.stages.base import check_output_folder, log_config, write_json
from onionsort.stages.lineup import (
    LineupRecorder,
    _classifier,
    _inspection_summary,
    evaluate_lineup,
)

__all__ = ["POLICIES", "EvaluateConfig", "evaluate", "evaluate_runs"]

logger = logging.getLogger(__name__)

def _policy(config: EvaluateConfig):
    """``(actions (48,), model document)`` of the policy ``config`` evaluates."""
    if config.policy == "expert":
        from irl.domains.onion_sorting import onion_sorting

        return (onion_sorting().expert_policy().argmax(axis=1),
                {"method": "expert", "policy": "the task's true (expert) policy"})
    return load_policy(config.run)


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
        from irl.demonstrations import StepTruth
        from robot.world import WorldFrame

        view, t = self._view, int(event.step)
        if view is None:
            raise RuntimeError("the evaluation reported a step before its start")
        time_ns = round(view.time_s * 1e9)
        self.writer.write_decision(event, frame=t, time_ns=time_ns)
        self.writer.write_frame(WorldFrame(
            index=t, step=StepTruth(step=t, state=int(event.state), action=int(event.action),
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
            "policy": (doc["policy"] if config.policy == "expert"
                       else f"greedy policy of {Path(config.run) / 'model.json'}")}


def evaluate(config: EvaluateConfig, models=None):
    """Evaluate a policy; write ``evaluation.json`` (and ``.rrd``, ``.mcap``) into
    ``config.folder``.

    ``models`` (:class:`~onionsort.stages.models.PerceptionModels`) are used instead of loading
    ``config.models`` again, as ``demo`` does for its many evaluations.

    Returns ``(result, summary)``: the :class:`robot.evaluation.SortingResult` and the dict
    written to ``evaluation.json``.
    """
    resolved = log_config("evaluate", config)
    actions, doc = _policy(config)
    confidence = None
    if config.defer_below is not None:
        confidence = load_confidence(config.run, policy=actions, per_action=True)
    import torch

    from onionsort.stages.parallel import torch_threads

    torch.set_num_threads(torch_threads())
    if config.lineup is not None:
        return evaluate_lineup(config, actions, doc, confidence, models)
    if config.record_lineup is not None:
        LineupRecorder.check(config.record_lineup)
    folder = config.folder
    check_output_folder(folder, "--out" if config.out is not None else "RUN_DIR")
    if config.connect is not None:
        from recordings.rerun.common import reach_viewer

        reach_viewer(config.connect)

    from recordings.labels.sorting_csv import TALLY_FILE, tally_rows, write_tally
    from robot.camera import CameraSpec, intrinsics
    from robot.evaluation import evaluate_policy
    from robot.station import station_robot
    from robot.station_cameras import ROBOT_INSPECTION_CAMERA
    from robot.world import camera_pose

    classify, inspector = _classifier(config, models, config.difficulty)
    # the boxes the inspection found, for the Rerun log
    detect = None if inspector is None else inspector.detections

    on_step, recorder = [], None
    lineup = None if config.record_lineup is None else \
        LineupRecorder(config.record_lineup, config.seed)
    if lineup is not None:
        on_step.append(lineup.on_step)
    session = folder / "evaluation.mcap"
    partial = session.with_name(session.name + ".partial")
    try:
        with contextlib.ExitStack() as stack:
            logged = config.rerun or config.connect is not None
            if logged:
                from onionsort.stages.evaluate_rerun import EvaluationLogger
                from recordings.rerun.common import rerun_targets

                on_step.append(stack.enter_context(EvaluationLogger(
                    rerun_targets(folder / "evaluation.rrd" if config.rerun else None,
                                  config.connect), detector=detect,
                    camera_K=intrinsics(CameraSpec()), robot=station_robot(),
                    camera_pose=camera_pose(CameraSpec()),
                    views=config.inspection_views, threshold=config.threshold,
                    inspection_K=intrinsics(ROBOT_INSPECTION_CAMERA),
                    inspection_pose=camera_pose(ROBOT_INSPECTION_CAMERA))).on_step)
            if config.mcap:
                from recordings import SessionWriter

                recorder = _SessionRecorder(stack.enter_context(SessionWriter(
                    partial, _session_metadata(config, doc, resolved), intrinsics(CameraSpec()),
                    intrinsics(ROBOT_INSPECTION_CAMERA), frames_per_step=1, overwrite=True)))
                on_step.append(recorder.on_step)

            def each_step(event) -> None:
                for call in on_step:
                    call(event)

            result = evaluate_policy(
                actions, n_onions=config.onions, n_blemished=config.blemished,
                seed=config.seed, classify=classify, render=logged or config.mcap,
                difficulty=config.difficulty, on_step=each_step if on_step else None,
                on_start=None if recorder is None else recorder.on_start,
                inspection_views=config.inspection_views,
                stop_when_settled=not config.every_view, confidence=confidence,
                defer_below=config.defer_below or 0.0)
            if lineup is not None:
                lineup.finish(np.array([o.blemished for o in result.onions]))
        if recorder is not None:
            partial.replace(session)
    finally:
        partial.unlink(missing_ok=True)  # a run that failed leaves no session behind
        if lineup is not None:
            lineup.discard()
    summary = {"method": doc.get("method"), "policy": config.policy, "seed": config.seed,
               "difficulty": config.difficulty, "lineups": [config.seed],
               **_inspection_summary(config, inspector), **result.to_dict()}
    if lineup is not None:
        summary["recorded_lineup"] = str(config.record_lineup)
    write_tally(folder / TALLY_FILE, tally_rows(config.seed, result.onions))
    write_json(folder / "evaluation.json", summary)
    return result, summary


def evaluate_runs(configs: list[EvaluateConfig], options=None) -> list[tuple[Any, dict]]:
    """Evaluate several runs as parallel pieces (:mod:`onionsort.stages.parallel`), each
    writing into its own folder what :func:`evaluate` alone writes; the models load once per
    worker. Returns ``(result, summary)`` per config, in order."""
    from onionsort.stages.parallel import ParallelOptions, run_pieces

    folders = [c.folder.resolve() for c in configs]
    if len(configs) > 1 and any(c.record_lineup is not None for c in configs):
        raise ValueError("--record-lineup records one run's line-up; evaluate one RUN_DIR "
                         "(or --policy expert) with it")
    if len(set(folders)) != len(folders):
        raise ValueError("each evaluation needs a folder of its own; got "
                         + ", ".join(str(c.folder) for c in configs))
    for c in configs:  # refused before any piece starts
        check_output_folder(c.folder, "--out" if c.out is not None else "RUN_DIR")
        _policy(c)
    out: list[Any] = [None] * len(configs)
    for i, done in run_pieces(_evaluate_piece, configs, options or ParallelOptions(workers=1),
                              names=[str(c.folder) for c in configs], desc="evaluate",
                              unit="run"):
        out[i] = done
    return out


def _evaluate_piece(config: EvaluateConfig):
    """One evaluation, with the models this worker loaded once."""
    from onionsort.stages.models import PerceptionModels

    models = None if config.ground_truth_inspection else \
        PerceptionModels.load_cached(config.models, config.device)
    return evaluate(config, models)
