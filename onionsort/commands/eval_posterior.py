"""``onionsort eval-posterior``: how well MMAP-BIRL's posterior knows what it does not know.

On synthetic problems of a domain, where the expert is known: problem i draws a few short
demonstrations (--trajectories of --length steps, at --noise and --occlusion) with seed
SEED + i, samples the posterior over rewards (--method: HMC chains, or the Laplace
approximation) and scores it against the expert's greedy action, on the states the expert
visited and on every state of the domain: the share of states whose credible action set at
50/80/90/95% holds the expert's action (coverage) and the sets' mean size, and how well
1 - the confidence in the MAP action flags the states where that action is wrong (AUROC).
The problems run on the workers (--workers); what they score does not depend on where.

Examples
--------
    onionsort eval-posterior sorting                      # 40 problems, HMC chains
    onionsort eval-posterior sorting --method laplace     # seconds
    onionsort eval-posterior forestworld --problems 10 --noise 0.3 --json
"""

from __future__ import annotations

import json
from dataclasses import dataclass

from onionsort.commands import add_command
from onionsort.configs import config_from_args, option
from onionsort.configs.eval_posterior import PosteriorEvalConfig


@dataclass(frozen=True, kw_only=True)
class EvalPosteriorCommand(PosteriorEvalConfig):
    """The command's options: the stage's, and ``--json``."""

    json: bool = option(False, after="backend", help="print one JSON object")


def register(subparsers) -> None:
    add_command(subparsers, "eval-posterior", __doc__,
                "score the posterior's credible action sets on synthetic problems",
                EvalPosteriorCommand, run)


def run(args) -> int:
    import numpy as np

    from onionsort.stages.eval_posterior import eval_posterior

    r = eval_posterior(config_from_args(PosteriorEvalConfig, args))
    if args.json:
        print(json.dumps(r))
        return 0
    c = r["config"]
    print(f"{c['domain']}, noise {c['noise']}: {c['problems']} problems of "
          f"{c['trajectories']} demonstrations x {c['length']} steps, occlusion "
          f"{c['occlusion']}; {c['method']}, {c['samples']} samples; seeds {c['seed']}.."
          f"{c['seed'] + c['problems'] - 1}")
    for scope, what in (("visited", "the states the expert visited"),
                        ("all", "every state (those no demonstration showed too)")):
        s = r[scope]
        print(f"\n{what}: {s['pairs']} (problem, state) pairs")
        print(f"{'level':>6}{'coverage':>10}{'mean set size':>15}")
        for level, cover in s["coverage"].items():
            print(f"{float(level):>6.0%}{cover:>10.3f}{s['mean_set_size'][level]:>15.2f}")
        auc = "undefined" if s["auroc"] is None else f"{s['auroc']:.3f}"
        print(f"AUROC of 1 - confidence in the MAP action, for 'the MAP action is not the "
              f"expert's': {auc} ({s['map_wrong']} such pairs, {s['map_right']} others)")
    r_hats = r["max_r_hat"]
    if all(v is not None for v in r_hats):
        print(f"\nmax R-hat per problem: mean {np.mean(r_hats):.4f}, worst {max(r_hats):.4f}, "
              f"{sum(v > 1.01 for v in r_hats)} of {len(r_hats)} above 1.01; divergences "
              f"{r['divergent']}")
    else:
        print("\nmax R-hat: none (the Laplace draws are independent)")
    print(f"sampling: median {np.median(r['seconds']):.2f} s a problem, "
          f"{sum(r['seconds']):.1f} s in all")
    return 0
