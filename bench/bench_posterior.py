"""Benchmark: sampling the posterior of MMAP-BIRL, Laplace against MCMC, and each against a fit.

Onion sorting at noise 0.3 (``irl.domains.onion_sorting(noise=0.3)``), 12 demonstrations of 20
steps at occlusion 0.2 (seed ``--seed``, 0), MMAP-BIRL with the domain's beta and prior and
``--backend``. In one run the bench times, each on a fresh (unfitted) estimator (the median is
printed; the fit and Laplace, which take a fraction of a second, run 5 times, MCMC
``--repeats`` times, 1):

- one MAP fit, ``est.fit(demos)``;
- ``irl.posterior.sample_posterior(est, demos, method="laplace")``, default settings;
- ``irl.posterior.sample_posterior(est, demos, method="mcmc")``, default settings.

Both samplers find the MAP themselves, so each includes one fit. Before the clock starts, one
fit runs as a warm-up (imports, the numba backend's compilation) and ``mici`` is imported; both
are timed and printed apart. The bench prints seconds, max R-hat, min ESS and gradients of each,
the ratio MCMC / Laplace and each one's ratio to the fit, what each says of the MAP policy
(the probability that it is optimal, its expected ILE), and whether the floors were met: MCMC
with max R-hat <= 1.01 in under 30 s, Laplace in under 2 s.

Then one evaluation of the log posterior alone (``est.log_posterior_value_function(demos)``,
what the importance proposals of the posterior over session readings call) against one with
its gradient (``est.log_posterior_function(demos)``, what the chains call), at the same
``--points`` thetas (200, the Laplace draws), in ``--rounds`` rounds (5) that alternate which
goes first: the median seconds of each, their ratio, and the largest difference of the values
(0: the value is the same number).

``--compare-emcee`` (``pip install emcee``) also runs ``emcee``'s ensemble sampler (stretch
move, 4K walkers started from the Laplace draws) on the same exact log posterior for as many
evaluations as the HMC chains took gradients, and prints its split R-hat over the walkers
(the last two thirds) and its autocorrelation time: why the HMC sampler was chosen.

The bench runs OpenBLAS on one thread (``OPENBLAS_NUM_THREADS=1`` unless set), as
``bench/bench_irl.py`` does: at these sizes a thread pool only adds synchronization. ``--clock
cpu`` reads this process's CPU time instead of wall time: on a machine shared with other work,
wall time measures the wait for a core as much as the work.

Example
-------
    python bench/bench_posterior.py                    # about a minute
    python bench/bench_posterior.py --clock cpu        # a shared machine
    python bench/bench_posterior.py --backend numba
    python bench/bench_posterior.py --compare-emcee
    python bench/bench_posterior.py --points 50 --rounds 3
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy loads; see the docstring

import numpy as np

import irl
from irl.inference import scratch_held
from irl.posterior import map_policy_risk, sample_posterior
from irl.stats import split_rhat

NOISE, N_DEMOS, LENGTH, OCCLUSION = 0.3, 12, 20, 0.2
MCMC_SECONDS, MCMC_R_HAT, LAPLACE_SECONDS = 30.0, 1.01, 2.0
#: The clock every timing reads: wall time, or this process's CPU time (``--clock cpu``).
CLOCK = time.perf_counter


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--backend", choices=("numpy", "numba"), default="numpy",
                        help="MMAPBIRL's forward-backward kernels (numpy)")
    parser.add_argument("--seed", type=int, default=0,
                        help="seed of the demonstrations and the samplers (0)")
    parser.add_argument("--repeats", type=int, default=1,
                        help="timed runs of MCMC (1); the fit and Laplace run max(5, this)")
    parser.add_argument("--compare-emcee", action="store_true",
                        help="also run emcee's ensemble sampler on the same budget")
    parser.add_argument("--clock", choices=["wall", "cpu"], default="wall",
                        help="what every timing reads: wall time (default), or this process's "
                             "CPU time (a shared machine)")
    parser.add_argument("--points", type=int, default=200,
                        help="thetas of the value-alone timing (200)")
    parser.add_argument("--rounds", type=int, default=5,
                        help="rounds of the value-alone timing (5)")
    args = parser.parse_args()
    for name in ("repeats", "points", "rounds"):
        if getattr(args, name) < 1:
            parser.error(f"--{name} must be >= 1")
    global CLOCK
    CLOCK = time.process_time if args.clock == "cpu" else time.perf_counter

    dom = irl.domains.onion_sorting(noise=NOISE)
    demos, _ = dom.sample(n=N_DEMOS, length=LENGTH, occlusion=OCCLUSION, seed=args.seed)

    def estimator() -> irl.MMAPBIRL:
        return irl.MMAPBIRL(dom.mdp, dom.observation_model, beta=dom.beta, prior=dom.prior,
                            backend=args.backend)

    t0 = CLOCK()
    estimator().fit(demos)
    warmup = CLOCK() - t0
    t0 = CLOCK()
    import mici  # noqa: F401  (the MCMC sampler's import, timed apart)

    mici_import = CLOCK() - t0

    fits, runs = [], {"laplace": [], "mcmc": []}
    posts = {}
    n_runs = {"fit": max(5, args.repeats), "laplace": max(5, args.repeats),
              "mcmc": args.repeats}
    for _ in range(n_runs["fit"]):
        t0 = CLOCK()
        fitted = estimator().fit(demos)
        fits.append(CLOCK() - t0)
    for method in runs:
        for _ in range(n_runs[method]):
            t0 = CLOCK()
            posts[method] = sample_posterior(estimator(), demos, seed=args.seed, method=method)
            runs[method].append(CLOCK() - t0)
    fit_s = statistics.median(fits)
    secs = {m: statistics.median(v) for m, v in runs.items()}

    print(f"onion sorting, noise {NOISE}: {N_DEMOS} demonstrations x {LENGTH} steps, "
          f"occlusion {OCCLUSION}, seed {args.seed}; MMAPBIRL backend {args.backend}; "
          f"{args.clock} time")
    print(f"warm-up fit (imports, compilation) {warmup:.2f} s; import mici {mici_import:.2f} s "
          f"(neither counted below)")
    print()
    print(f"{'run':<9}{'runs':>5}{'seconds':>9}{'x fit':>8}{'max R-hat':>11}{'min ESS':>9}"
          f"{'gradients':>11}{'accept':>8}{'diverg.':>9}")
    print(f"{'MAP fit':<9}{n_runs['fit']:>5}{fit_s:>9.3f}{1.0:>8.1f}{'':>48}"
          f"   ({fitted.n_iter_} iterations)")
    for method in ("laplace", "mcmc"):
        d = posts[method].diagnostics
        r_hat = d.max_r_hat()
        r_hat_txt = "n/a" if not np.isfinite(r_hat) else f"{r_hat:.4f}"
        print(f"{method:<9}{n_runs[method]:>5}{secs[method]:>9.3f}"
              f"{secs[method] / fit_s:>8.1f}{r_hat_txt:>11}{float(np.min(d.ess)):>9.0f}"
              f"{d.n_gradients:>11}{d.acceptance:>8.3f}{d.n_divergent:>9}")
    print()
    print(f"mcmc / laplace time: {secs['mcmc'] / secs['laplace']:.1f}x")
    r_hat = posts["mcmc"].diagnostics.max_r_hat()
    mcmc_ok = r_hat <= MCMC_R_HAT and secs["mcmc"] < MCMC_SECONDS
    laplace_ok = secs["laplace"] < LAPLACE_SECONDS
    print(f"mcmc: max R-hat {r_hat:.4f} <= {MCMC_R_HAT} and {secs['mcmc']:.1f} s < "
          f"{MCMC_SECONDS:.0f} s: {'met' if mcmc_ok else 'NOT met'}")
    print(f"laplace: {secs['laplace']:.2f} s < {LAPLACE_SECONDS:.0f} s: "
          f"{'met' if laplace_ok else 'NOT met'}")
    print()
    for method in ("laplace", "mcmc"):
        risk = map_policy_risk(posts[method], dom.mdp)
        print(f"{method}: P(the MAP policy is optimal) {risk.p_optimal:.3f}, expected ILE "
              f"{risk.expected_ile:.2f} (normalized {risk.expected_normalized_ile:.2f}%)")
    value_alone(estimator().fit(demos), demos, args.points, args.rounds, args.seed)
    if args.compare_emcee:
        compare_emcee(estimator(), demos, posts, args.seed)


def value_alone(est, demos, points: int, rounds: int, seed: int) -> None:
    """One log posterior evaluation alone against one with its gradient, at the Laplace
    draws, in rounds that alternate which goes first."""
    value_and_grad = est.log_posterior_function(demos)
    value = est.log_posterior_value_function(demos)
    thetas = sample_posterior(est, demos, n_samples=points, seed=seed, method="laplace").theta
    times = {"value": [], "value_and_grad": []}
    with scratch_held():
        diff = max(abs(value(t) - value_and_grad(t)[0]) for t in thetas)  # and a warm-up
        for r in range(rounds):
            pair = [("value", value), ("value_and_grad", value_and_grad)]
            for name, f in pair if r % 2 == 0 else pair[::-1]:
                t0 = CLOCK()
                for t in thetas:
                    f(t)
                times[name].append((CLOCK() - t0) / points)
    v, vg = (statistics.median(times[k]) for k in ("value", "value_and_grad"))
    print()
    print(f"log posterior at {points} thetas, {rounds} rounds: value alone {v * 1e3:.3f} ms, "
          f"with its gradient {vg * 1e3:.3f} ms: {v / vg:.2f}x; largest difference of the "
          f"values {diff:.1e}")


def compare_emcee(est, demos, posts, seed: int) -> None:
    """emcee's stretch-move ensemble on the same log posterior and budget as the HMC chains."""
    import emcee

    value_and_grad = est.log_posterior_function(demos)
    laplace, mcmc = posts["laplace"], posts["mcmc"]
    K = laplace.theta.shape[1]
    walkers = 4 * K
    steps = mcmc.diagnostics.n_gradients // walkers
    sampler = emcee.EnsembleSampler(walkers, K, lambda t: value_and_grad(t)[0])
    t0 = CLOCK()
    sampler.run_mcmc(laplace.theta[:walkers], steps, progress=False)
    seconds = CLOCK() - t0
    chain = np.swapaxes(sampler.get_chain(discard=steps // 3), 0, 1)  # (walkers, draws, K)
    r_hat = max(split_rhat(chain[:, :, k]) for k in range(K))
    tau = sampler.get_autocorr_time(discard=steps // 3, quiet=True)
    print()
    print(f"emcee: {walkers} walkers x {steps} steps ({walkers * steps} log posteriors, the "
          f"HMC chains took {mcmc.diagnostics.n_gradients} gradients) in {seconds:.1f} s: "
          f"max split R-hat {r_hat:.3f}, autocorrelation time {np.max(tau):.0f} steps, "
          f"acceptance {np.mean(sampler.acceptance_fraction):.2f}")


if __name__ == "__main__":
    main()
