"""Stage ``learn``: an offline learning run from perceived sessions.

The learner sees only the perceived observations of each session (occluded where the classifier
said so), never ground truth, through the observation model of a calibration. The calibration
must have been measured with the same perception models (their hashes) and in the same depth
mode as the sessions were perceived; ``allow_model_mismatch`` overrides the refusal.

Writes into ``out``: ``model.json`` (method, learned reward weights with feature names, the
greedy policy with state and action names, the inputs, the forward-backward backend),
``learning_curve.json`` and ``.png``, and ``learn.rrd`` (Rerun), which ``connect`` also streams
to a viewer on another machine.

Example::

    from onionsort.stages import LearnConfig, learn
    model = learn(LearnConfig(sessions=(Path("runs/rec/session_000.mcap"),),
                              calibration=Path("runs/calibration/calibration.json"),
                              out=Path("runs/learn-mmap")))
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from onionsort.stages.base import log_config, output_folder, refuse_existing, write_json
from onionsort.stages.models import model_mismatch

if TYPE_CHECKING:
    from irl.domains.task import TaskDescription

__all__ = ["MODEL_FILE", "LearnConfig", "learn", "load_policy"]

logger = logging.getLogger(__name__)

MODEL_FILE = "model.json"
MODEL_FORMAT = "onionsort.learned-model/1"


@dataclass(frozen=True)
class LearnConfig:
    """What to learn from, with which learner, into which run folder.

    Attributes
    ----------
    sessions : tuple of Path
        Perceived session files.
    calibration : Path
        ``calibration.json`` from ``onionsort calibrate``.
    out : Path
        Run folder.
    method : str
        A learner of :data:`irl.experiments.METHODS`.
    seed : int
    allow_model_mismatch : bool
        Learn even when the sessions were perceived by other models, or in another sensor
        mode, than the calibration was measured with (logged, and noted in ``model.json``).
    rerun : bool
        Write ``learn.rrd``.
    overwrite : bool
        Replace an earlier run's ``model.json`` in ``out``.
    connect : str or None
        Also stream the Rerun recording to the viewer at this gRPC URL
        (``rerun+http://HOST:9876/proxy``), in addition to ``learn.rrd``.
    backend : str
        Forward-backward kernels (``irl.inference.BACKENDS``): ``numpy`` or ``numba`` (the
        ``fast`` extra), equal to rounding; used by the methods that run forward-backward
        (``mmap-birl``, ``hidden-data-em``), recorded in ``model.json`` for every method.
    """

    sessions: tuple[Path, ...]
    calibration: Path
    out: Path
    method: str = "mmap-birl"
    seed: int = 0
    allow_model_mismatch: bool = False
    rerun: bool = True
    overwrite: bool = False
    connect: str | None = None
    backend: str = "numpy"

    def __post_init__(self) -> None:
        from irl.experiments import METHODS
        from irl.inference import check_backend

        if self.method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}; got {self.method!r}")
        check_backend(self.backend)
        if not self.sessions:
            raise ValueError("sessions must name at least one session file; got none")
        missing = [str(p) for p in self.sessions if not Path(p).is_file()]
        if missing:
            raise FileNotFoundError(f"no such session file(s): {', '.join(missing)}")
        if self.connect is not None:
            from recordings.rerun.common import check_viewer_url

            check_viewer_url(self.connect)


def _check_provenance(session, calibration, calibration_path: Path) -> None:
    """Refuse a session perceived by other models, or in another mode, than the calibration."""
    record = session.perception_models or {}
    differ = model_mismatch(record, calibration.models) if calibration.models else []
    if differ:
        raise ValueError(
            f"{session.path} was perceived by other models than {calibration_path} was "
            f"measured with ({', '.join(differ)} differ); perceive it again with the "
            "calibration's models, recalibrate, or pass --allow-model-mismatch")
    sensors = ("depth", "inspection")
    perceived = {k: bool(record.get(k, True)) for k in sensors}
    differ = [k for k in sensors
              if getattr(calibration, k) is not None and getattr(calibration, k) != perceived[k]]
    if differ:
        said = {True: "with", False: "without"}
        flags = " ".join(f"--no-{k}" for k in sensors if not perceived[k])
        shipped = ""
        if not perceived["depth"]:
            shipped = (" (or use the shipped calibration-video.json)" if perceived["inspection"]
                       else " (or use the shipped calibration-video-no-inspection.json)")
        raise ValueError(
            f"{session.path} was perceived "
            + " and ".join(f"{said[perceived[k]]} {k}" for k in differ)
            + f" but {calibration_path} was measured "
            + " and ".join(f"{said[getattr(calibration, k)]} {k}" for k in differ)
            + f"; calibrate in the sessions' mode (`onionsort calibrate {flags or '...'}`)"
            + f"{shipped}, or pass --allow-model-mismatch")


def learn(config: LearnConfig) -> dict:
    """Fit the learner on the perceived sessions; write the run folder; return ``model.json``."""
    import dataclasses

    from irl.domains.onion_sorting import onion_sorting
    from irl.experiments import make_estimator
    from irl.learners.optimize import objective_curve
    from onionsort.plots import learning_curve_figure
    from recordings import open_session
    from state_abstraction.calibration import load_calibration

    log_config("learn", config)
    refuse_existing(config.out / MODEL_FILE, config.overwrite)
    if config.connect is not None:
        from recordings.rerun.common import reach_viewer

        reach_viewer(config.connect)  # a wrong address fails now, not after the fit
    with output_folder(config.out) as out:  # checked before anything is read or fitted
        base = onion_sorting()
        calibration = load_calibration(config.calibration, task=base.task)
        sessions = [open_session(p) for p in config.sessions]
        for session in sessions:
            if session.task != base.task:
                raise ValueError(f"{session.path} records the task {session.task.name!r}, not "
                                 f"{base.task.name!r} that learn fits")
        mismatch = []
        for session in sessions:
            try:
                if session.perception:
                    _check_provenance(session, calibration, config.calibration)
            except ValueError as exc:
                if not config.allow_model_mismatch:
                    raise
                mismatch.append(str(exc))
                logger.warning("allowed by --allow-model-mismatch: %s", exc)
        demos = [s.perceived_demonstration() for s in sessions]
        domain = dataclasses.replace(base, observation_model=calibration.observation_model())
        estimator = make_estimator(config.method, domain, seed=config.seed,
                                   backend=config.backend)
        estimator.fit(demos)
        theta = np.asarray(estimator.theta_, float)
        policy = np.asarray(estimator.policy_, int)
        model = {
            "format": MODEL_FORMAT, "method": config.method, "backend": config.backend,
            "theta": dict(zip(domain.feature_names, theta.round(6).tolist(), strict=True)),
            "policy": [{"state": domain.state_names[s], "action": domain.action_names[a]}
                       for s, a in enumerate(policy)],
            "policy_indices": policy.tolist(),
            "sessions": [str(p) for p in config.sessions],
            "n_steps": sum(len(d) for d in demos),
            "n_occluded": sum(d.n_occluded for d in demos),
            "observation_model": str(config.calibration),
            "state_error_rate": calibration.state_error_rate,
            "n_iter": int(getattr(estimator, "n_iter_", 0)),
            "model_mismatch_allowed": mismatch,
        }
        history = list(getattr(estimator, "history_", []))
        write_json(out / "learning_curve.json", history)
        write_json(out / MODEL_FILE, model)
        learning_curve_figure(objective_curve(history)[1], config.method,
                              out / "learning_curve.png")
        if config.rerun or config.connect is not None:
            from recordings.rerun import log_learning
            from recordings.rerun.common import rerun_targets

            log_learning(rerun_targets(out / "learn.rrd" if config.rerun else None,
                                       config.connect), model, history)
    return model


def load_policy(run_dir: Path, task: TaskDescription | None = None):
    """The greedy policy ``actions[s]`` (S,) of a learning run and its model.json, with clear
    errors; ``task`` (the onion-sorting task by default) gives the numbers of states and
    actions."""
    import json

    from irl.domains.onion_sorting import SORTING_TASK

    task = SORTING_TASK if task is None else task
    n_states, n_actions = task.n_states, task.n_actions
    path = Path(run_dir) / MODEL_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{run_dir} holds no learned model (no {MODEL_FILE}); run "
                                "`onionsort learn ... --out RUN_DIR` first")
    try:
        doc = json.loads(path.read_text())
        actions = np.asarray(doc["policy_indices"], dtype=np.int64)
    except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{path} is not a learned model ({exc})") from None
    if actions.shape != (n_states,) or actions.min() < 0 or actions.max() >= n_actions:
        raise ValueError(f"{path}: the policy must give one action in [0, {n_actions}) for each "
                         f"of the {n_states} {task.name} states; got shape {actions.shape}")
    return actions, doc
