"""Calibration of the posterior's action confidence on onion sorting (issue 24).

For each of ``--problems`` problems (problem ``i`` draws its demonstrations with seed
``--seed + i`` and samples with the same seed; the default base 1000 is one nothing was tuned
on), the bench draws 2 demonstrations of 10 steps from ``irl.domains.onion_sorting(noise=0.45)``
at occlusion 0.2, and samples the posterior of MMAP-BIRL (the domain's beta and prior) with
``irl.posterior.sample_posterior(..., n_samples=1000, method=--method)``.

It is scored on the states the expert visited (the true states of the trajectories, each state
once per problem), against the expert's greedy action ``dom.optimal_policy()[s]``:

- coverage: the share of (problem, visited state) pairs whose credible action set at level
  50/80/90/95% holds the expert's action, and the mean size of that set;
- AUROC: how well ``1 - confidence in the MAP's action`` ranks the visited states where the
  MAP policy's action differs from the expert's above those where it agrees (Mann-Whitney,
  ties averaged), with the number of positives (MAP wrong) and negatives.

It prints one table of coverage and set size per level, the AUROC, the mean over problems of
the max R-hat (NaN for Laplace) and the total time, with the floors of issue 24 beside: 90%
coverage >= 0.85, AUROC >= 0.75. The states the expert visits are the ones two short
demonstrations show best, where the MAP is seldom wrong; the same scores over all 48 states of
every problem (the states the robot may reach and no demonstration showed) follow, a harder
test of the same confidence.

Example
-------
    python bench/posterior_calibration.py                     # 40 problems, MCMC
    python bench/posterior_calibration.py --method laplace    # seconds
    python bench/posterior_calibration.py --problems 10 --json /tmp/calibration.json
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from scipy.stats import rankdata

import irl
from irl.posterior import METHODS, sample_posterior

LEVELS = (0.5, 0.8, 0.9, 0.95)
NOISE, N_DEMOS, LENGTH, OCCLUSION, N_SAMPLES = 0.45, 2, 10, 0.2, 1000
COVERAGE_FLOOR, AUROC_FLOOR = 0.85, 0.75


def auroc(scores: np.ndarray, labels: np.ndarray) -> float:
    """Area under the ROC curve of ``scores`` for the ``labels`` (True = positive), by the
    Mann-Whitney rank formula with tied scores given their average rank; NaN without both
    classes."""
    labels = np.asarray(labels, bool)
    n_pos, n_neg = int(labels.sum()), int((~labels).sum())
    if n_pos == 0 or n_neg == 0:
        return float("nan")
    ranks = rankdata(scores)  # ties averaged
    return float((ranks[labels].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * n_neg))


def problem(dom, expert: np.ndarray, seed: int, method: str) -> dict:
    """One problem's scores on the states the expert visited."""
    demos, trajectories = dom.sample(n=N_DEMOS, length=LENGTH, occlusion=OCCLUSION, seed=seed)
    est = irl.MMAPBIRL(dom.mdp, dom.observation_model, beta=dom.beta, prior=dom.prior)
    t0 = time.perf_counter()
    post = sample_posterior(est, demos, n_samples=N_SAMPLES, seed=seed, method=method)
    seconds = time.perf_counter() - t0
    visited = np.unique(np.concatenate([tr.states for tr in trajectories]))
    scopes = {"visited": visited, "all": np.arange(dom.mdp.n_states)}
    out = {"seed": seed, "seconds": seconds, "max_r_hat": post.diagnostics.max_r_hat(),
           "n_divergent": post.diagnostics.n_divergent}
    for scope, states in scopes.items():
        covered, size = {}, {}
        for level in LEVELS:
            sets = post.credible_actions(level)
            covered[level] = [int(expert[s]) in sets[s] for s in states]
            size[level] = [len(sets[s]) for s in states]
        out[scope] = {"n": int(states.size), "covered": covered, "size": size,
                      "risk": (1.0 - post.map_confidence()[states]).tolist(),
                      "map_wrong": (post.map_policy[states] != expert[states]).tolist()}
    return out


def summarize(results: list[dict], scope: str) -> dict:
    """Coverage and set size per level, and the AUROC, over one scope of states."""
    rows = [r[scope] for r in results]
    risk = np.concatenate([r["risk"] for r in rows])
    wrong = np.concatenate([r["map_wrong"] for r in rows]).astype(bool)
    return {
        "n_pairs": sum(r["n"] for r in rows),
        "coverage": {lv: float(np.mean(np.concatenate([r["covered"][lv] for r in rows])))
                     for lv in LEVELS},
        "mean_size": {lv: float(np.mean(np.concatenate([r["size"][lv] for r in rows])))
                      for lv in LEVELS},
        "auroc": auroc(risk, wrong), "n_pos": int(wrong.sum()), "n_neg": int((~wrong).sum()),
    }


def report(summary: dict, what: str) -> None:
    coverage, mean_size = summary["coverage"], summary["mean_size"]
    n_pos, n_neg, area = summary["n_pos"], summary["n_neg"], summary["auroc"]
    print(f"{summary['n_pairs']} (problem, {what}) pairs")
    print(f"{'level':>6}{'coverage':>10}{'mean set size':>15}{'floor':>8}{'met':>5}")
    for lv in LEVELS:
        floor = f"{COVERAGE_FLOOR:.2f}" if lv == 0.9 else ""
        met = ("yes" if coverage[lv] >= COVERAGE_FLOOR else "NO") if lv == 0.9 else ""
        print(f"{lv:>6.0%}{coverage[lv]:>10.3f}{mean_size[lv]:>15.2f}{floor:>8}{met:>5}")
    if n_pos == 0 or n_neg == 0:
        print(f"AUROC: undefined ({n_pos} states where the MAP action differs from the "
              f"expert's, {n_neg} where it agrees)")
    else:
        print(f"AUROC of 1 - MAP confidence for 'MAP action != expert's': {area:.3f}  "
              f"(floor {AUROC_FLOOR:.2f}: {'met' if area >= AUROC_FLOOR else 'NOT met'}; "
              f"{n_pos} positives, {n_neg} negatives)")
    print()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--problems", type=int, default=40, help="problems (40)")
    parser.add_argument("--method", choices=METHODS, default="mcmc", help="sampler (mcmc)")
    parser.add_argument("--seed", type=int, default=1000,
                        help="seed base: problem i uses seed + i (1000)")
    parser.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    args = parser.parse_args()
    if args.problems < 1:
        parser.error("--problems must be >= 1")

    dom = irl.domains.onion_sorting(noise=NOISE)
    expert = np.asarray(dom.optimal_policy())
    t0 = time.perf_counter()
    results = [problem(dom, expert, args.seed + i, args.method) for i in range(args.problems)]
    total = time.perf_counter() - t0

    summaries = {scope: summarize(results, scope) for scope in ("visited", "all")}
    r_hats = np.array([r["max_r_hat"] for r in results])
    mean_r_hat = float(np.mean(r_hats)) if np.all(np.isfinite(r_hats)) else float("nan")
    worst_r_hat = float(np.max(r_hats)) if np.all(np.isfinite(r_hats)) else float("nan")
    per_problem = [r["seconds"] for r in results]

    print(f"onion sorting, noise {NOISE}: {args.problems} problems of {N_DEMOS} demonstrations "
          f"x {LENGTH} steps, occlusion {OCCLUSION}; method {args.method}, "
          f"{N_SAMPLES} samples; seeds {args.seed}..{args.seed + args.problems - 1}")
    print()
    report(summaries["visited"], "visited state")
    print("the same over all 48 states (those no demonstration showed included):")
    report(summaries["all"], "state")
    if np.isfinite(mean_r_hat):
        print(f"max R-hat per problem: mean {mean_r_hat:.4f}, worst {worst_r_hat:.4f}, "
              f"{int(np.sum(r_hats > 1.01))} of {args.problems} above 1.01; "
              f"divergences {sum(r['n_divergent'] for r in results)}")
    else:
        print("max R-hat: n/a (Laplace draws are independent)")
    print(f"time: {total:.1f} s in all, {total / args.problems:.2f} s a problem "
          f"(sample_posterior: median {np.median(per_problem):.2f} s, "
          f"max {np.max(per_problem):.2f} s)")

    if args.json is not None:
        def finite(x: float) -> float | None:
            return None if not np.isfinite(x) else round(float(x), 6)

        def scores(summary: dict) -> dict:
            return {"n_pairs": summary["n_pairs"],
                    "coverage": {f"{lv:.2f}": round(v, 6)
                                 for lv, v in summary["coverage"].items()},
                    "mean_set_size": {f"{lv:.2f}": round(v, 6)
                                      for lv, v in summary["mean_size"].items()},
                    "auroc": finite(summary["auroc"]), "n_positives": summary["n_pos"],
                    "n_negatives": summary["n_neg"]}

        visited = summaries["visited"]
        args.json.write_text(json.dumps({
            "method": args.method, "problems": args.problems, "seed": args.seed,
            "noise": NOISE, "n_demos": N_DEMOS, "length": LENGTH, "occlusion": OCCLUSION,
            "n_samples": N_SAMPLES, "visited": scores(visited),
            "all_states": scores(summaries["all"]),
            "mean_max_r_hat": finite(mean_r_hat), "worst_max_r_hat": finite(worst_r_hat),
            "max_r_hat_per_problem": [finite(v) for v in r_hats],
            "n_divergent": sum(r["n_divergent"] for r in results),
            "seconds": round(total, 3),
            "seconds_per_problem": [round(s, 3) for s in per_problem],
            "floors": {"coverage_90": COVERAGE_FLOOR, "auroc": AUROC_FLOOR},
            "met": {"coverage_90": visited["coverage"][0.9] >= COVERAGE_FLOOR,
                    "auroc": bool(np.isfinite(visited["auroc"])
                                  and visited["auroc"] >= AUROC_FLOOR)},
        }, indent=2) + "\n")
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
