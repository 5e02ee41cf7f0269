"""``onionsort experiment``: the paper's sweeps (Fig. 1b-d on Forestworld, Fig. 3a-b on sorting).

Examples
--------
    onionsort experiment forestworld --quick --out runs/forestworld-quick
    onionsort experiment forestworld --out runs/forestworld          # the paper's full sweep
    onionsort experiment sorting --occlusion 0.1,0.2,0.3,0.4 --noise 0.3 --out runs/sorting
"""

from __future__ import annotations

import argparse
import csv
import json
import logging
import os
from dataclasses import asdict
from pathlib import Path

logger = logging.getLogger(__name__)

#: The paper's sweeps: (occlusion, noise) points per domain.
PAPER_POINTS = {
    # Fig. 1b: occlusion 10-40% at noise 0 and 30%; Fig. 1c: noise 20-45% without occlusion.
    "forestworld": [(o, n) for n in (0.0, 0.3) for o in (0.1, 0.2, 0.3, 0.4)]
    + [(0.0, n) for n in (0.2, 0.25, 0.3, 0.35, 0.4, 0.45)],
    # Fig. 3a-b: occlusion at the estimated 30% noise.
    "sorting": [(o, 0.3) for o in (0.0, 0.1, 0.2, 0.3, 0.4)],
}
QUICK_POINTS = {
    "forestworld": [(0.1, 0.3), (0.3, 0.3), (0.0, 0.2), (0.0, 0.4)],
    "sorting": [(0.1, 0.3), (0.3, 0.3)],
}
CSV_COLUMNS = ["method", "occlusion", "noise", "batch", "ile", "seconds",
               "normalized_ile", "n_iter", "converged"]


def _floats(text: str) -> list[float]:
    try:
        return [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        msg = f"expected comma-separated numbers; got {text!r}"
        raise argparse.ArgumentTypeError(msg) from None


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "experiment", help="ILE and run-time sweeps of the paper's figures",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("domain", choices=["forestworld", "sorting"])
    p.add_argument("--occlusion", type=_floats, help="occlusion rates, e.g. 0.1,0.2,0.3")
    p.add_argument("--noise", type=_floats, help="observation-noise levels, e.g. 0,0.3")
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


def build_config(args):
    from irl.experiments import SweepConfig

    if args.occlusion is not None or args.noise is not None:
        occ = args.occlusion if args.occlusion is not None else [0.0]
        noise = args.noise if args.noise is not None else [0.3]
        points = [(o, n) for n in noise for o in occ]
    else:
        points = (QUICK_POINTS if args.quick else PAPER_POINTS)[args.domain]
    defaults = {"batches": 3 if args.quick else 10, "trajectories": 10,
                "length": 15 if args.domain == "forestworld" else 20}
    return SweepConfig(
        domain=args.domain,
        points=tuple(points),
        methods=tuple(m.strip() for m in args.methods.split(",") if m.strip()),
        batches=args.batches or defaults["batches"],
        trajectories=args.trajectories or defaults["trajectories"],
        length=args.length or defaults["length"],
        seed=args.seed,
    )


def run(args) -> int:
    from tqdm import tqdm

    from irl.experiments import run_sweep, summarize
    from onionsort.plots import plot_sweep

    config = build_config(args)
    out = args.out or Path("runs") / f"experiment-{args.domain}"
    out.mkdir(parents=True, exist_ok=True)
    logger.info("config: %s", config)
    trials = config.trials()
    results = []
    partial = out / "results.csv.partial"
    with partial.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=CSV_COLUMNS)
        writer.writeheader()
        for r in tqdm(run_sweep(config, workers=args.workers), total=len(trials),
                      desc=f"{args.domain} sweep", unit="fit"):
            results.append(r)
            writer.writerow(asdict(r))
            fh.flush()
    partial.replace(out / "results.csv")
    summary = {"config": asdict(config), "workers": args.workers, "points": summarize(results)}
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    plots = plot_sweep(results, out, title=args.domain)
    print(format_table(summary["points"]))
    print(f"wrote {out / 'results.csv'}, {out / 'summary.json'} and {len(plots)} plots to {out}")
    return 0


def format_table(points: list[dict]) -> str:
    lines = [f"{'method':<16}{'occlusion':>10}{'noise':>7}{'ILE mean':>12}{'ILE std':>10}"
             f"{'nILE %':>9}{'seconds':>10}"]
    for p in points:
        lines.append(
            f"{p['method']:<16}{p['occlusion']:>10.2f}{p['noise']:>7.2f}{p['ile_mean']:>12.2f}"
            f"{p['ile_std']:>10.2f}{p['normalized_ile_mean']:>9.3f}{p['seconds_mean']:>10.3f}"
        )
    return "\n".join(lines)
