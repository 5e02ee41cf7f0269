"""``onionsort demo``: record, perceive, calibrate, learn and evaluate: the whole job.

Records 12 sessions of a person sorting onions while a passer-by blocks the camera, perceives
them with the shipped models, calibrates the observation model on fresh held-out frames, learns
the sorter's reward with MMAP-BIRL, MAP-BIRL and HiddenDataEM, lets the Sawyer sort 50 onions
with each learned policy (its inspection as ``onionsort evaluate``'s: ``--inspection-views``,
``--miss-cost``, ``--waste-cost``, ``--fusion``) and prints the paper's Table 1 beside ours.
``--quick`` runs it small. ``--methods`` picks other learners, e.g. behaviour cloning (``bc``,
``bc-em``) beside MMAP-BIRL. It ends by writing ``report.md`` in --out (``onionsort report``).
``--resume`` continues an interrupted demo in its --out from the last finished stage (same
results as an uninterrupted run); ``--connect URL`` streams the Rerun recordings to a viewer on
another machine as well.

Examples
--------
    onionsort demo
    onionsort demo --quick --out runs/demo-quick
    onionsort demo --quick --out runs/demo-quick --resume
    onionsort demo --connect rerun+http://192.168.1.20:9876/proxy
    onionsort demo --methods mmap-birl,map-birl,bc,bc-em --out runs/demo-bc   # + cloning
"""

from __future__ import annotations

from pathlib import Path

from onionsort.commands._args import (
    METHODS,
    add_backend_argument,
    add_connect_argument,
    add_defer_argument,
    add_device_argument,
    add_inspection_arguments,
    add_models_argument,
    add_parallel_arguments,
    add_posterior_method_argument,
    add_session_swaps_argument,
    methods_list,
    parallel_options,
    subcommand,
)


def register(subparsers) -> None:
    from robot.difficulty import DIFFICULTY_LEVELS

    parser = subcommand(subparsers, "demo", __doc__,
                        "record, perceive, calibrate, learn and evaluate: the whole job")
    parser.add_argument("--seed", type=int, default=0, help="root seed (0)")
    parser.add_argument("--out", type=Path, default=Path("runs/demo"),
                        help="run folder (runs/demo)")
    parser.add_argument("--quick", action="store_true", help="a small, fast run (smoke test)")
    parser.add_argument("--sessions", type=int, help="sessions recorded per repeat (12; quick 4)")
    parser.add_argument("--difficulty", choices=list(DIFFICULTY_LEVELS), default="clean",
                        help="how hard the world makes perception (clean)")
    parser.add_argument("--methods", type=methods_list(METHODS),
                        default=("mmap-birl", "map-birl", "hidden-data-em"),
                        metavar="METHOD[,METHOD...]",
                        help="the learners whose policies the Sawyer sorts with ("
                             + ", ".join(METHODS) + "; default mmap-birl,map-birl,"
                             "hidden-data-em)")
    parser.add_argument("--repeats", type=int, default=1,
                        help="repeat with seeds SEED..SEED+K-1 and report 95%% intervals (1)")
    add_models_argument(parser)
    parser.add_argument("--resume", action="store_true",
                        help="continue the interrupted demo in --out: skip its finished stages")
    add_connect_argument(parser, what="the recordings of record, learn and evaluate")
    add_backend_argument(parser)
    add_inspection_arguments(parser)
    add_device_argument(parser)
    add_defer_argument(parser, needs="MMAP-BIRL and MAP-BIRL then also learn the posterior, "
                                     "and sort the same line-up once more deferring")
    add_posterior_method_argument(parser)
    add_session_swaps_argument(parser)
    add_parallel_arguments(parser, pieces="repeats' recordings and methods")
    parser.set_defaults(func=run)


def run(args) -> int:
    from onionsort.stages import DemoConfig, demo
    from onionsort.stages.demo import table

    results = demo(DemoConfig(out=args.out, seed=args.seed, quick=args.quick,
                              models=args.models, sessions=args.sessions, repeats=args.repeats,
                              difficulty=args.difficulty, connect=args.connect,
                              resume=args.resume, backend=args.backend,
                              inspection_views=args.inspection_views,
                              miss_cost=args.miss_cost, waste_cost=args.waste_cost,
                              fusion=args.fusion, device=args.device,
                              defer_below=args.defer_below,
                              posterior_method=args.posterior_method,
                              session_swaps=args.session_swaps, methods=args.methods,
                              **parallel_options(args)))
    print(f"effective noise: state error rate {results['state_error_rate']:.3f}, "
          f"(state, action) error rate {results['pair_error_rate']:.3f}")
    if results.get("sessions_read_backwards"):
        from onionsort.stages.calibrate import describe_session_swaps

        print(f"held-out sessions: {describe_session_swaps(results['sessions_read_backwards'])}")
    print(table(results))
    print(f"wrote {args.out / 'results.json'} ({results['seconds']:.0f} s)")
    print(f"report: {args.out / 'report.md'}")
    return 0
