"""``onionsort learn``: an offline learning run from perceived MCAP sessions.

The sessions must have been perceived (``onionsort perceive``): the learner sees only the
perceived observations, with occluded steps where the classifier said so, never the ground
truth. The observation model comes from ``onionsort calibrate``.

Writes into ``OUT``: ``model.json`` (method, learned reward weights with feature names, the
greedy policy with state and action names, the inputs), ``learning_curve.json`` and
``learning_curve.png``, and ``learn.rrd`` (a Rerun recording of the run).

Examples
--------
    onionsort learn runs/rec/*.mcap --method mmap-birl \\
        --observation-model runs/calibration/calibration.json --out runs/learn-mmap
    onionsort learn runs/rec/*.mcap --method hidden-data-em \\
        --observation-model runs/calibration/calibration.json --out runs/learn-em
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

__all__ = ["learn", "register"]

logger = logging.getLogger(__name__)

MODEL_FILE = "model.json"
MODEL_FORMAT = "onionsort.learned-model/1"


def register(subparsers) -> None:
    """Add the ``learn`` subcommand."""
    from irl.experiments import METHODS

    parser = subparsers.add_parser(
        "learn", help="learn the sorter's reward from perceived sessions (offline run)",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("sessions", type=Path, nargs="+", metavar="SESSION.mcap")
    parser.add_argument("--method", choices=METHODS, default="mmap-birl")
    parser.add_argument("--observation-model", type=Path, required=True, metavar="FILE",
                        help="calibration.json written by `onionsort calibrate`")
    parser.add_argument("--out", type=Path, required=True, help="run folder")
    parser.add_argument("--seed", type=int, default=0)
    parser.set_defaults(func=run)


def learn(sessions, method: str, calibration_path: Path, out: Path, seed: int = 0) -> dict:
    """Fit ``method`` on the perceived sessions; write the run folder; return ``model.json``."""

    import dataclasses

    import numpy as np

    from irl.domains.onion_sorting import onion_sorting
    from irl.experiments import make_estimator
    from recordings import open_session
    from state_abstraction.calibration import load_calibration

    calibration = load_calibration(calibration_path)
    demos = [open_session(p).perceived_demonstration() for p in sessions]
    domain = dataclasses.replace(onion_sorting(),
                                 observation_model=calibration.observation_model())
    estimator = make_estimator(method, domain, seed=seed)
    estimator.fit(demos)
    theta = np.asarray(estimator.theta_, float)
    policy = np.asarray(estimator.policy_, int)
    out.mkdir(parents=True, exist_ok=True)
    model = {
        "format": MODEL_FORMAT, "method": method,
        "theta": dict(zip(domain.feature_names, theta.round(6).tolist(), strict=True)),
        "policy": [{"state": domain.state_names[s], "action": domain.action_names[a]}
                   for s, a in enumerate(policy)],
        "policy_indices": policy.tolist(),
        "sessions": [str(p) for p in sessions],
        "n_steps": sum(len(d) for d in demos),
        "n_occluded": sum(d.n_occluded for d in demos),
        "observation_model": str(calibration_path),
        "state_error_rate": calibration.state_error_rate,
        "n_iter": int(getattr(estimator, "n_iter_", 0)),
    }
    history = list(getattr(estimator, "history_", []))
    _write_json(out / "learning_curve.json", history)
    _write_json(out / MODEL_FILE, model)
    _plot_curve(history, method, out / "learning_curve.png")
    _log_rerun(model, history, out / "learn.rrd")
    return model


def _write_json(path: Path, doc) -> None:
    import json

    tmp = path.with_name(path.name + ".partial")
    tmp.write_text(json.dumps(doc, indent=1))
    tmp.replace(path)


def _curve(history: list[dict]) -> list[float]:
    key = next((k for k in ("value", "log_likelihood") if history and k in history[0]), None)
    return [float(h[key]) for h in history] if key else []


def _plot_curve(history, method: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3.2))
    ax.plot(_curve(history), ".-")
    ax.set_xlabel("iteration")
    ax.set_ylabel("objective (log posterior / log likelihood)")
    ax.set_title(method)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _log_rerun(model: dict, history, path: Path) -> None:
    import rerun as rr

    rec = rr.RecordingStream("onionsort_learn")
    rec.save(path)
    for k, v in enumerate(_curve(history)):
        rec.set_time("iteration", sequence=k)
        rec.log("learn/objective", rr.Scalars(v))
    rec.log("learn/theta", rr.TextDocument("\n".join(
        f"{name}: {w:+.3f}" for name, w in model["theta"].items())), static=True)
    rec.log("learn/policy", rr.TextDocument("\n".join(
        f"{row['state']} -> {row['action']}" for row in model["policy"])), static=True)
    rec.flush()
    rec.disconnect()


def run(args: argparse.Namespace) -> int:
    missing = [str(p) for p in args.sessions if not p.is_file()]
    if missing:
        raise FileNotFoundError(f"no such session file(s): {', '.join(missing)}")
    model = learn(args.sessions, args.method, args.observation_model, args.out, args.seed)
    print(f"{args.method}: learned from {len(args.sessions)} sessions ({model['n_steps']} steps, "
          f"{model['n_occluded']} occluded)")
    print("  theta: " + ", ".join(f"{k} {v:+.2f}" for k, v in model["theta"].items()))
    print(f"wrote {args.out / MODEL_FILE}")
    return 0
