"""Behaviour cloning's rule for states never seen: uniform against the most common action.

``irl.BehaviorCloning(unseen=...)`` smooths every state toward, and gives a state never
visited, either the uniform distribution (its greedy action uniformly random) or the actions'
overall frequencies (its greedy action the most common one). This bench measures both rules,
for both variants (``face-value`` and ``em``), on the data-efficiency sweep of docs/results.md
(onion sorting, 20% occlusion, 30% and 45% noise, 1, 2, 4 and 8 demonstrations of 20 steps), on
sweep seeds that no reported result uses (9038 and 9039 by default), and prints the mean
normalized ILE and exact-policy rate per cell, then how many cells each rule wins on
normalized ILE. The learners' default (``"uniform"``) was chosen from its output. Last, the
floor of cloning on that table: the normalized ILE of the expert's own action on the 10 states
the expert reaches and a uniformly random action on the 38 others (``--draws`` draws).

Example
-------
    python bench/cloning_unseen.py                     # seeds 9038, 9039; 10 batches (~1 min)
    python bench/cloning_unseen.py --seeds 1,2 --batches 5
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from irl.domains.onion_sorting import onion_sorting, reachable_states
from irl.experiments import SweepConfig, run_sweep, summarize
from irl.learners import BehaviorCloning, LearnerSpec, register_learner, unregister_learner
from irl.learners.cloning import UNSEEN, VARIANTS
from irl.metrics import normalized_inverse_learning_error
from irl.solvers import OptimalQSolver


def _spec(variant: str, unseen: str) -> LearnerSpec:
    def build(domain, *, seed=None):
        return BehaviorCloning(domain.mdp, domain.observation_model, variant=variant,
                               unseen=unseen, seed=seed)

    return LearnerSpec(f"bench-{variant}-{unseen}", f"cloning, {variant}, {unseen}", build)


def _random_off_the_path(draws: int) -> np.ndarray:
    """Normalized ILE of policies that are the expert's on its reachable states and uniformly
    random elsewhere (seeded: draws from ``default_rng(0)``)."""
    dom = onion_sorting()
    expert = OptimalQSolver(dom.mdp).solve(dom.true_theta).policy
    on_path = np.asarray(reachable_states())
    rng = np.random.default_rng(0)
    out = np.empty(draws)
    for i in range(draws):
        policy = rng.integers(0, dom.mdp.n_actions, dom.mdp.n_states)
        policy[on_path] = expert[on_path]
        out[i] = normalized_inverse_learning_error(dom.mdp, dom.true_theta, policy=policy)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", default="9038,9039", help="sweep seeds, comma-separated")
    parser.add_argument("--batches", type=int, default=10, help="batches per cell (10)")
    parser.add_argument("--draws", type=int, default=200,
                        help="random policies of the floor (200)")
    args = parser.parse_args(argv)
    seeds = [int(s) for s in args.seeds.split(",")]
    specs = {(v, u): _spec(v, u) for v in VARIANTS for u in UNSEEN}
    for spec in specs.values():
        register_learner(spec)
    start = time.perf_counter()
    try:
        rows = []
        for seed in seeds:
            config = SweepConfig("sorting", points=((0.2, 0.3), (0.2, 0.45)),
                                 methods=tuple(s.name for s in specs.values()),
                                 batches=args.batches, trajectories=(1, 2, 4, 8), length=20,
                                 seed=seed)
            rows += [{**r, "seed": seed} for r in summarize(run_sweep(config), seed=seed)]
    finally:
        for spec in specs.values():
            unregister_learner(spec.name)
    cell = {(r["method"], r["seed"], r["noise"], r["trajectories"]): r for r in rows}
    print("variant     seed  noise demos | " + " | ".join(
        f"{u:>11s} nILE  exact" for u in UNSEEN))
    wins = {(v, u): 0 for v, u in specs}
    for variant in VARIANTS:
        for seed in seeds:
            for noise in (0.3, 0.45):
                for n in (1, 2, 4, 8):
                    got = {u: cell[specs[variant, u].name, seed, noise, n] for u in UNSEEN}
                    print(f"{variant:10s} {seed:5d} {noise:5.2f} {n:5d} | " + " | ".join(
                        f"{got[u]['normalized_ile_mean']:16.1f} {got[u]['exact_policy_rate']:6.2f}"
                        for u in UNSEEN))
                    best = min(got[u]["normalized_ile_mean"] for u in UNSEEN)
                    for u in UNSEEN:
                        wins[variant, u] += got[u]["normalized_ile_mean"] == best
    cells = len(seeds) * 8
    for (variant, unseen), n in wins.items():
        print(f"{variant}, unseen={unseen}: lowest (or tied) normalized ILE in {n} of {cells} "
              "cells")
    floor = _random_off_the_path(args.draws)
    print(f"the expert's action on its reachable states, a uniformly random one elsewhere: "
          f"normalized ILE {floor.mean():.1f}% (5-95%: {np.percentile(floor, 5):.1f}-"
          f"{np.percentile(floor, 95):.1f}%, {args.draws} draws)")
    print(f"{time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
