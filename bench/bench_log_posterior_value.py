"""Benchmark: MMAP-BIRL's log posterior alone against the log posterior with its gradient.

Onion sorting at noise 0.3 (``irl.domains.onion_sorting(noise=0.3)``), ``--demos``
demonstrations (12) of ``--length`` steps (20) at occlusion 0.2 (seed 0), MMAP-BIRL with the
domain's beta and prior, on each backend installed. The two prepared functions,
``est.log_posterior_value_function(demos)`` (what the importance proposals of
:func:`irl.posterior.importance._importance_draws` call) and
``est.log_posterior_function(demos)`` (what the chains call), are evaluated at the same
``--points`` thetas (200), the Laplace approximation's draws (``sample_posterior(est, demos,
method="laplace")``, round which a reading's importance proposals are drawn), in rounds that
alternate which goes first (``--rounds``, 5); the bench prints the median seconds per
evaluation of each, their ratio, and the largest difference of their values.

Example
-------
    python bench/bench_log_posterior_value.py
    python bench/bench_log_posterior_value.py --demos 3 --length 200
"""

from __future__ import annotations

import argparse
import importlib.util
import statistics
import time

import irl
from irl.inference import scratch_held
from irl.posterior import sample_posterior


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--demos", type=int, default=12, help="demonstrations (12)")
    parser.add_argument("--length", type=int, default=20, help="steps of each (20)")
    parser.add_argument("--points", type=int, default=200, help="thetas evaluated (200)")
    parser.add_argument("--rounds", type=int, default=5, help="timed rounds (5)")
    args = parser.parse_args()
    for name in ("demos", "length", "points", "rounds"):
        if getattr(args, name) < 1:
            parser.error(f"--{name} must be >= 1")
    dom = irl.domains.onion_sorting(noise=0.3)
    demos, _ = dom.sample(n=args.demos, length=args.length, occlusion=0.2, seed=0)
    backends = ["numpy"] + (["numba"] if importlib.util.find_spec("numba") else [])
    print(f"onion sorting, {args.demos} demonstrations of {args.length} steps, "
          f"{args.points} thetas a round, {args.rounds} rounds (median seconds per evaluation)")
    for backend in backends:
        est = irl.MMAPBIRL(dom.mdp, dom.observation_model, beta=dom.beta, prior=dom.prior,
                           backend=backend).fit(demos)
        value_and_grad = est.log_posterior_function(demos)
        value = est.log_posterior_value_function(demos)
        thetas = sample_posterior(est, demos, n_samples=args.points, seed=0,
                                  method="laplace").theta
        times = {"value": [], "value_and_grad": []}
        with scratch_held():
            diff = max(abs(value(t) - value_and_grad(t)[0]) for t in thetas)  # and warm-up
            for r in range(args.rounds):
                pair = [("value", value), ("value_and_grad", value_and_grad)]
                for name, f in pair if r % 2 == 0 else pair[::-1]:
                    t0 = time.perf_counter()
                    for t in thetas:
                        f(t)
                    times[name].append((time.perf_counter() - t0) / args.points)
        v, vg = (statistics.median(times[k]) for k in ("value", "value_and_grad"))
        print(f"{backend}: value {v * 1e3:.3f} ms, value and gradient {vg * 1e3:.3f} ms, "
              f"ratio {v / vg:.2f}x; largest difference of the values {diff:.1e}")


if __name__ == "__main__":
    main()
