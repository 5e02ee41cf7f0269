"""Stage ``learn``: an offline learning run from perceived sessions.

The learner sees only the perceived observations of each session (occluded where the classifier
said so), never ground truth, through the observation model of a calibration. The calibration
must have been measured with the same perception models (their hashes) and in the same depth
mode as the sessions were perceived; ``allow_model_mismatch`` overrides the refusal.

Writes into ``out``: ``model.json`` (method, learned reward weights with feature names, the
greedy policy with state and action names, the inputs, the forward-backward backend; for
behaviour cloning, ``bc`` and ``bc-em``, no weights (``theta`` null) but each policy action's
probability and the states never seen),
``learning_curve.json`` and ``.png``, and ``learn.rrd`` (Rerun), which ``connect`` also streams
to a viewer on another machine. With ``posterior``, the Bayesian learners also draw the
posterior over reward weights (:mod:`irl.posterior`) and write ``posterior.npz``,
``policy_confidence.json`` (per state, each action's confidence, the 90% credible actions, the
MAP policy's risk and the sampler's diagnostics) and ``policy_confidence.png``.

Example::

    from onionsort.stages import LearnConfig, learn
    model = learn(LearnConfig(sessions=(Path("runs/rec/session_000.mcap"),),
                              calibration=Path("runs/calibration/calibration.json"),
                              out=Path("runs/learn-mmap")))
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from onionsort.configs.learn import BAYESIAN_METHODS as BAYESIAN_METHODS
from onionsort.configs.learn import SWAP_METHOD as SWAP_METHOD
from onionsort.configs.learn import LearnConfig
from onionsort.policy import (
    CONFIDENCE_FILE,
    CONFIDENCE_FORMAT,
    MODEL_FILE,
    MODEL_FORMAT,
    load_confidence,
    load_policy,
)
from onionsort.stages.base import log_config, output_folder, refuse_existing, write_json
from onionsort.stages.models import model_mismatch
from onionsort.stages.parallel import ParallelOptions

__all__ = ["CONFIDENCE_FILE", "MODEL_FILE", "MODEL_FORMAT", "POSTERIOR_FILE", "LearnConfig",
           "learn", "learn_methods", "load_confidence", "load_policy"]

logger = logging.getLogger(__name__)

POSTERIOR_FILE = "posterior.npz"
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
    from irl.domains.onion_sorting import onion_sorting
    from irl.experiments import make_estimator
    from irl.learners.optimize import objective_curve
    from irl.priors import GaussianPrior
    from onionsort.plots import learning_curve_figure
    from recordings import open_session
    from state_abstraction.calibration import load_calibration

    log_config("learn", config)
    refuse_existing(config.out / MODEL_FILE, config.overwrite)
    if config.connect is not None:
        from recordings.rerun.common import reach_viewer

        reach_viewer(config.connect)  # a wrong address fails now, not after the fit
    with output_folder(config.out) as out:  # checked before anything is read or fitted
        base = dataclasses.replace(onion_sorting(beta=config.beta),
                                   prior=GaussianPrior(mean=0.0, std=config.prior_std))
        calibration = load_calibration(config.calibration, task=base.task)
        if config.session_swaps and calibration.session_swaps is None:
            raise ValueError(f"{config.calibration} does not say how often a whole session's "
                             "reads of the onion's class were backwards, which "
                             "--session-swaps needs; calibrate again with this version")
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
        # with the swaps modelled, the confusion within a session given how it was read
        domain = dataclasses.replace(base, observation_model=calibration.observation_model(
            within_sessions=config.session_swaps))
        estimator = make_estimator(config.method, domain, seed=config.seed,
                                   backend=config.backend)
        if config.session_swaps:
            estimator.session_swap = calibration.session_swap()
        estimator.fit(demos)
        policy = np.asarray(estimator.policy_, int)
        # behaviour cloning learns no reward (theta None) but the probability of each action
        cloned = getattr(estimator, "action_probabilities_", None)
        model = {
            "format": MODEL_FORMAT, "method": config.method, "backend": config.backend,
            "theta": None if estimator.theta_ is None else dict(zip(
                domain.feature_names, np.asarray(estimator.theta_, float).round(6).tolist(),
                strict=True)),
            "policy": [{"state": domain.state_names[s], "action": domain.action_names[a],
                        **({} if cloned is None else
                           {"probability": round(float(cloned[s, a]), 4)})}
                       for s, a in enumerate(policy)],
            "policy_indices": policy.tolist(),
            "sessions": [str(p) for p in config.sessions],
            "n_steps": sum(len(d) for d in demos),
            "n_occluded": sum(d.n_occluded for d in demos),
            "observation_model": str(config.calibration),
            "state_error_rate": calibration.state_error_rate,
            "n_iter": int(getattr(estimator, "n_iter_", 0)),
            "beta": config.beta, "prior_std": config.prior_std,
            "model_mismatch_allowed": mismatch,
        }
        if cloned is not None:
            model["unseen_states"] = [domain.state_names[s] for s in estimator.unseen_states_]
        if config.session_swaps:
            model["session_swaps"] = {
                "rate": estimator.session_swap.rate,
                "p_swapped": [round(float(p), 4) for p in
                              estimator.swap_probabilities(estimator.theta_, demos)]}
        confidence = None
        if config.posterior:
            confidence = _sample_posterior(config, estimator, demos, domain, out)
            model["posterior"] = {k: confidence[k] for k in ("method", "n_samples", "risk")}
        history = list(getattr(estimator, "history_", []))
        write_json(out / "learning_curve.json", history)
        write_json(out / MODEL_FILE, model)
        learning_curve_figure(objective_curve(history)[1], config.method,
                              out / "learning_curve.png")
        if config.rerun or config.connect is not None:
            from onionsort.stages.learn_rerun import log_learning
            from recordings.rerun.common import rerun_targets

            log_learning(rerun_targets(out / "learn.rrd" if config.rerun else None,
                                       config.connect), model, history, confidence=confidence)
    return model


def learn_methods(config: LearnConfig, methods: Sequence[str],
                  options: ParallelOptions | None = None) -> dict[str, dict]:
    """Learn with several methods from the same sessions, each into ``config.out / method``,
    as parallel pieces (:mod:`onionsort.stages.parallel`); return each method's model.json.
    Each method's run is the one ``learn`` alone writes (its seed is ``config.seed``)."""
    from onionsort.stages.parallel import run_pieces

    methods = list(dict.fromkeys(methods))
    if not methods:
        raise ValueError("methods must name at least one learner; got none")
    configs = [dataclasses.replace(config, method=m, out=Path(config.out) / m,
                                   session_swaps=config.session_swaps and m == SWAP_METHOD)
               for m in methods]
    for c in configs:  # refused before any piece starts
        refuse_existing(c.out / MODEL_FILE, c.overwrite)
    models: dict[str, dict] = {}
    for i, model in run_pieces(learn, configs, options or ParallelOptions(workers=1),
                               names=[f"{m} ({c.out})" for m, c in zip(methods, configs,
                                                                       strict=True)],
                               desc="learn", unit="method"):
        models[methods[i]] = model
    return {m: models[m] for m in methods}


def _sample_posterior(config: LearnConfig, estimator, demos, domain, out: Path) -> dict:
    """Sample the posterior; write posterior.npz, policy_confidence.json and .png; return the
    confidence document."""
    from irl.domains.onion_sorting import describe_state
    from irl.posterior import map_policy_risk, sample_posterior
    from onionsort.plots import confidence_figure

    post = sample_posterior(estimator, demos, n_samples=config.samples, seed=config.seed,
                            method=config.posterior_method)
    post.save(out / POSTERIOR_FILE)
    risk = map_policy_risk(post, domain.mdp)
    conf = post.action_confidence()
    actions = domain.action_names
    doc = {
        "format": CONFIDENCE_FORMAT, "method": config.posterior_method,
        "n_samples": post.n_samples, "diagnostics": post.diagnostics.to_dict(),
        "risk": risk.to_dict(),
        "states": [
            {"state": domain.state_names[s], "description": describe_state(s),
             "map_action": actions[int(post.map_policy[s])],
             "confidence": {a: round(float(c), 4) for a, c in zip(actions, row, strict=True)},
             "credible_90": [actions[a] for a in credible]}
            for s, (row, credible) in enumerate(zip(conf, post.credible_actions(0.9),
                                                    strict=True))],
    }
    if post.components:  # the readings of the sessions (which were read swapped) weighed
        doc["readings"] = [{"swapped": list(c.swapped), "weight": round(c.weight, 6),
                            "n_samples": c.n_samples} for c in post.components]
    write_json(out / CONFIDENCE_FILE, doc)
    confidence_figure(conf, post.map_policy, domain.state_names, actions,
                      out / "policy_confidence.png")
    logger.info("posterior (%s, %d samples): P(the MAP policy is optimal) %.3f, expected ILE "
                "%.3f, max R-hat %s", config.posterior_method, post.n_samples, risk.p_optimal,
                risk.expected_ile, doc["diagnostics"]["r_hat"])
    return doc
