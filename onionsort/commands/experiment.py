"""``onionsort experiment``: the paper's sweeps (Fig. 1b-d on Forestworld, Fig. 3a-b on sorting).

Examples
--------
    onionsort experiment forestworld --quick --out runs/forestworld-quick
    onionsort experiment forestworld --out runs/forestworld          # the paper's full sweep
    onionsort experiment sorting --occlusion 0.1,0.2,0.3,0.4 --noise 0.3 --out runs/sorting
"""

from __future__ import annotations

import os
from pathlib import Path

from onionsort.commands._args import floats, subcommand


def register(subparsers) -> None:
    p = subcommand(subparsers, "experiment", __doc__,
                   "ILE and run-time sweeps of the paper's figures")
    p.add_argument("domain", choices=["forestworld", "sorting"])
    p.add_argument("--occlusion", type=floats, help="occlusion rates, e.g. 0.1,0.2,0.3")
    p.add_argument("--noise", type=floats, help="observation-noise levels, e.g. 0,0.3")
    p.add_argument("--batches", type=int, help="batches per point (default 10; quick 3)")
    p.add_argument("--trajectories", type=int, help="demonstrations per batch (default 10)")
    p.add_argument("--length", type=int, help="steps per demonstration (default 15 / 20)")
    p.add_argument("--methods", default="mmap-birl,map-birl,hidden-data-em,maxent",
                   help="comma-separated subset of mmap-birl,map-birl,hidden-data-em,maxent")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1),
                   help="parallel processes (run times are comparable within one run)")
    p.add_argument("--quick", action="store_true", help="a small sweep that takes seconds")
    p.add_argument("--out", type=Path, help="run folder (default runs/experiment-DOMAIN)")
    p.set_defaults(func=run)


def run(args) -> int:
    from onionsort.stages import ExperimentConfig, run_experiment
    from onionsort.stages.experiment import format_table

    config = ExperimentConfig(
        domain=args.domain, occlusion=args.occlusion, noise=args.noise, batches=args.batches,
        trajectories=args.trajectories, length=args.length,
        methods=tuple(m.strip() for m in args.methods.split(",") if m.strip()),
        seed=args.seed, workers=args.workers, quick=args.quick, out=args.out)
    summary = run_experiment(config)
    print(format_table(summary["points"]))
    print(f"wrote results.csv, summary.json and {len(summary['plots'])} plots to "
          f"{config.folder}")
    return 0
