"""``onionsort experiment``: the paper's sweeps (Fig. 1b-d, 3a-b) and data-efficiency sweeps.

Examples
--------
    onionsort experiment forestworld --quick --out runs/forestworld-quick
    onionsort experiment forestworld --out runs/forestworld          # the paper's full sweep
    onionsort experiment sorting --occlusion 0.1,0.2,0.3,0.4 --noise 0.3 --out runs/sorting
    onionsort experiment sorting --trajectories 1,2,4,8 --noise 0.3,0.45 --occlusion 0.2 \\
        --batches 20 --out runs/efficiency                 # 95% bootstrap intervals per point
    onionsort experiment sorting --trajectories 1,2,4,8 --noise 0.3,0.45 --occlusion 0.2 \\
        --batches 20 --methods mmap-birl,map-birl,bc,bc-em --out runs/efficiency-bc  # + cloning
    onionsort experiment sorting --trajectories 2,8 --noise 0.3 --occlusion 0.2 \\
        --learner-beta x0.25,x1,x4,paper --batches 20 --out runs/beta   # misspecified beta
    onionsort experiment forestworld --out runs/forestworld --resume   # after an interruption
    onionsort experiment sorting --quick --backend numba               # compiled kernels
    onionsort experiment forestworld --quick --executor ray            # a local Ray instance
    RAY_ADDRESS=head-node:6379 onionsort experiment forestworld --executor ray   # a cluster
"""

from __future__ import annotations

from pathlib import Path

from onionsort.commands._args import (
    IRL_METHODS,
    METHODS,
    add_backend_argument,
    add_parallel_arguments,
    floats,
    parallel_options,
    subcommand,
)


def register(subparsers) -> None:
    p = subcommand(subparsers, "experiment", __doc__,
                   "ILE and run-time sweeps of the paper's figures")
    p.add_argument("domain", choices=["forestworld", "sorting"])
    p.add_argument("--occlusion", type=floats, help="occlusion rates, e.g. 0.1,0.2,0.3")
    p.add_argument("--noise", type=floats, help="observation-noise levels, e.g. 0,0.3")
    p.add_argument("--batches", type=int, help="batches per point (default 10; quick 3)")
    p.add_argument("--trajectories", help="demonstrations per batch, e.g. 1,2,4,8 (default 10)")
    p.add_argument("--length", help="steps per demonstration, e.g. 10,20 (default 15 / 20)")
    p.add_argument("--learner-beta", help="beta the learners are fitted with: betas, factors of "
                   "the true beta (x0.5,x1,x2) or paper (0.03); default: the true beta")
    p.add_argument("--methods", default=",".join(IRL_METHODS),
                   help=f"comma-separated subset of {','.join(METHODS)} (default: the four "
                        "reward learners; bc and bc-em clone the policy, learning no reward)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--quick", action="store_true", help="a small sweep that takes seconds")
    add_backend_argument(p)
    p.add_argument("--out", type=Path, help="run folder (default runs/experiment-DOMAIN)")
    p.add_argument("--resume", action="store_true",
                   help="continue an interrupted sweep in --out: keep the trials in its "
                        "results.csv.partial and run the rest (same options; --backend may "
                        "differ)")
    add_parallel_arguments(p, pieces="trials")
    p.set_defaults(func=run)


def run(args) -> int:
    from onionsort.stages import ExperimentConfig, run_experiment
    from onionsort.stages.experiment import format_table, parse_list

    def listed(name, kind="int"):
        value = getattr(args, name.replace("-", "_"))
        return None if value is None else parse_list(value, name, kind)

    config = ExperimentConfig(
        domain=args.domain, occlusion=args.occlusion, noise=args.noise, batches=args.batches,
        trajectories=listed("trajectories"), length=listed("length"),
        learner_beta=listed("learner-beta", "learner"),
        methods=tuple(m.strip() for m in args.methods.split(",") if m.strip()),
        seed=args.seed, quick=args.quick, out=args.out,
        resume=args.resume, **parallel_options(args),
        backend=args.backend)
    summary = run_experiment(config)
    print(format_table(summary["points"]))
    print(f"wrote results.csv, summary.json and {len(summary['plots'])} plots to "
          f"{config.folder}")
    print(f"report: {summary['report']}")
    return 0
