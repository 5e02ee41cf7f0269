"""``onionsort learn``: learn the sorter's reward from perceived sessions (an offline run).

``--method bc`` or ``bc-em`` clones the sorter's policy instead (behaviour cloning, at face
value or through the observation model): no reward is learned.

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
    onionsort learn runs/rec/*.mcap --observation-model runs/calibration/calibration.json \\
        --out runs/learn-mmap --posterior            # + posterior.npz, policy_confidence.json
    onionsort learn runs/rec/*.mcap --observation-model runs/calibration/calibration.json \\
        --method mmap-birl,map-birl,hidden-data-em --out runs/learn   # runs/learn/<method>,
        # the methods in parallel (--workers, --executor ray)
    onionsort learn runs/rec/*.mcap --observation-model runs/calibration/calibration.json \\
        --method bc-em --out runs/learn-bc-em        # behaviour cloning, no reward
"""

from __future__ import annotations

from pathlib import Path

from onionsort.commands._args import (
    METHODS,
    add_backend_argument,
    add_connect_argument,
    add_parallel_arguments,
    add_posterior_method_argument,
    add_session_swaps_argument,
    methods_list,
    parallel_options,
    subcommand,
)


def register(subparsers) -> None:
    parser = subcommand(subparsers, "learn", __doc__,
                        "learn the sorter's reward from perceived sessions (offline run)")
    parser.add_argument("sessions", type=Path, nargs="+", metavar="SESSION.mcap")
    parser.add_argument("--method", type=methods_list(METHODS), default=("mmap-birl",),
                        metavar="METHOD[,METHOD...]",
                        help=f"the learner ({', '.join(METHODS)}; default mmap-birl); several, "
                             "comma-separated, learn in parallel, each into OUT/METHOD")
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
    add_session_swaps_argument(parser)
    add_backend_argument(parser)
    add_connect_argument(parser, what="the learning run (learn.rrd)")
    add_parallel_arguments(parser, pieces="methods")
    parser.set_defaults(func=run)


def run(args) -> int:
    from onionsort.stages import LearnConfig, learn
    from onionsort.stages.learn import SWAP_METHOD, learn_methods
    from onionsort.stages.parallel import ParallelOptions

    methods = args.method
    # the swaps concern MMAP-BIRL alone; learn_methods gives them to it and to no other
    first = SWAP_METHOD if args.session_swaps and SWAP_METHOD in methods else methods[0]
    config = LearnConfig(sessions=tuple(args.sessions), calibration=args.observation_model,
                         out=args.out, method=first, seed=args.seed,
                         allow_model_mismatch=args.allow_model_mismatch,
                         overwrite=args.overwrite, connect=args.connect,
                         backend=args.backend, posterior=args.posterior,
                         samples=args.samples, posterior_method=args.posterior_method,
                         session_swaps=args.session_swaps)
    if len(methods) == 1:
        models = {methods[0]: learn(config)}
        folders = {methods[0]: args.out}
    else:  # learn_methods checks every method's config before any piece starts
        models = learn_methods(config, methods, ParallelOptions(**parallel_options(args)))
        folders = {m: args.out / m for m in methods}
    for method, model in models.items():
        print(f"{method}: learned from {len(args.sessions)} session(s) ({model['n_steps']} "
              f"steps, {model['n_occluded']} occluded)")
        if model["theta"] is None:  # behaviour cloning
            print(f"  no reward (behaviour cloning): the policy copies the actions; "
                  f"{len(model['unseen_states'])} state(s) never seen")
        else:
            print("  theta: " + ", ".join(f"{k} {v:+.2f}" for k, v in model["theta"].items()))
        if "session_swaps" in model:
            print(f"  sessions read with the onion's class backwards (prior "
                  f"{model['session_swaps']['rate']:.3f}), posterior probability: "
                  + ", ".join(f"{p:.3f}" for p in model["session_swaps"]["p_swapped"]))
        if "posterior" in model:
            risk = model["posterior"]["risk"]
            print(f"  posterior ({args.posterior_method}, {model['posterior']['n_samples']} "
                  f"samples): P(the policy is optimal) {risk['p_map_optimal']:.3f}, expected "
                  f"ILE {risk['expected_ile']:.3f}")
            print(f"wrote {folders[method] / 'policy_confidence.json'}")
        print(f"wrote {folders[method] / 'model.json'}")
    return 0
