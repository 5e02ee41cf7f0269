"""``onionsort learn``: learn the sorter's reward from perceived sessions (an offline run).

The learner sees only the perceived observations (``onionsort perceive``), never ground truth,
through the observation model of ``onionsort calibrate``. Sessions perceived by other models, or
in another depth mode, than the calibration measured are refused (``--allow-model-mismatch``).
Writes ``model.json``, ``learning_curve.json``/``.png`` and ``learn.rrd`` into ``--out``;
``--connect URL`` also streams the Rerun recording to a viewer on another machine.

Examples
--------
    onionsort learn runs/rec/*.mcap --method mmap-birl \\
        --observation-model runs/calibration/calibration.json --out runs/learn-mmap
    onionsort learn runs/rec/*.mcap --observation-model runs/calibration/calibration.json \\
        --out runs/learn-mmap --connect rerun+http://192.168.1.20:9876/proxy
    onionsort learn runs/rec/*.mcap --observation-model runs/calibration/calibration.json \\
        --out runs/learn-mmap --backend numba       # compiled forward-backward (the fast extra)
    onionsort learn runs/rec/*.mcap --observation-model runs/calibration/calibration.json \
        --out runs/learn-mmap --posterior            # + posterior.npz, policy_confidence.json
"""

from __future__ import annotations

from pathlib import Path

from onionsort.commands._args import (
    add_backend_argument,
    add_connect_argument,
    add_posterior_method_argument,
    subcommand,
)


def register(subparsers) -> None:
    from irl.experiments import METHODS

    parser = subcommand(subparsers, "learn", __doc__,
                        "learn the sorter's reward from perceived sessions (offline run)")
    parser.add_argument("sessions", type=Path, nargs="+", metavar="SESSION.mcap")
    parser.add_argument("--method", choices=METHODS, default="mmap-birl",
                        help="the learner (mmap-birl)")
    parser.add_argument("--observation-model", type=Path, required=True, metavar="FILE",
                        help="calibration.json written by `onionsort calibrate`")
    parser.add_argument("--out", type=Path, required=True, help="run folder")
    parser.add_argument("--seed", type=int, default=0, help="the learner's seed (0)")
    parser.add_argument("--overwrite", action="store_true", help="replace an earlier run in --out")
    parser.add_argument("--allow-model-mismatch", action="store_true",
                        help="learn even if the sessions were perceived by other models (or "
                             "in another sensor mode) than the calibration measured")
    parser.add_argument("--posterior", action="store_true",
                        help="also sample the posterior over reward weights (mmap-birl, "
                             "map-birl): posterior.npz, policy_confidence.json and .png")
    parser.add_argument("--samples", type=int, default=1000, metavar="N",
                        help="posterior samples (1000)")
    add_posterior_method_argument(parser)
    add_backend_argument(parser)
    add_connect_argument(parser, what="the learning run (learn.rrd)")
    parser.set_defaults(func=run)


def run(args) -> int:
    from onionsort.stages import LearnConfig, learn

    model = learn(LearnConfig(sessions=tuple(args.sessions), calibration=args.observation_model,
                              out=args.out, method=args.method, seed=args.seed,
                              allow_model_mismatch=args.allow_model_mismatch,
                              overwrite=args.overwrite, connect=args.connect,
                              backend=args.backend, posterior=args.posterior,
                              samples=args.samples, posterior_method=args.posterior_method))
    print(f"{args.method}: learned from {len(args.sessions)} session(s) ({model['n_steps']} "
          f"steps, {model['n_occluded']} occluded)")
    print("  theta: " + ", ".join(f"{k} {v:+.2f}" for k, v in model["theta"].items()))
    if "posterior" in model:
        risk = model["posterior"]["risk"]
        print(f"  posterior ({args.posterior_method}, {model['posterior']['n_samples']} "
              f"samples): P(the policy is optimal) {risk['p_map_optimal']:.3f}, expected ILE "
              f"{risk['expected_ile']:.3f}")
        print(f"wrote {args.out / 'policy_confidence.json'}")
    print(f"wrote {args.out / 'model.json'}")
    return 0
