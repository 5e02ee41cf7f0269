"""Performance of the irl core, as ratios against baselines measured in the same run.

    python bench/bench_irl.py              # everything (about 6 minutes on 2 cores)
    python bench/bench_irl.py --quick      # one repeat, S up to 40,000 (about 2 minutes)
    python bench/bench_irl.py --clock cpu  # CPU time instead of wall time (a shared machine)
    python bench/bench_irl.py --scaling-only --clock cpu  # section 3 alone

BLAS threads: the bench runs OpenBLAS on one thread (``OPENBLAS_NUM_THREADS=1``, set before
numpy loads, unless the variable is already set), the library and its baseline alike: at these
sizes a BLAS thread pool only adds synchronization (scipy's L-BFGS-B makes tiny BLAS calls at
every iteration), and on a shared machine it makes timings swing.

Backends: the numpy/scipy path is the default and the reference; where numba is installed
(``pip install 'onionsort[fast]'``) the bench also times ``backend="numba"`` (compiled once,
before timing).

1. Sorting fit (12 demonstrations x 20 steps, 4 occluded each, 30% noise, 10 batches) and one
   warm gradient (also against a naive numpy forward pass of the same demonstrations, the
   likelihood alone: :func:`naive_forward`): MMAP-BIRL against the frozen path of commit cfdfae2
   (``bench/irl_baseline.py``: dense emission table, demonstrations re-packed at every
   gradient, the planning kernels and gradient assembly of that time) and against
   HiddenDataEM (the paper's "more than 10x faster").
2. One MMAP-BIRL gradient vs occlusion 0..60% (sorting, 12 demonstrations x 100 steps): flat.
3. Scaling in S (10,000 to 102,400 states, a 320 x 320 grid) on a grid world with sparse T,
   10 demonstrations x 100 steps, 20% occluded,
   peak memory from tracemalloc: (a) forward-backward against the frozen path, both with a
   100-block state sensor (wrong 30% of the time, uniformly: the largest model the frozen path
   can hold at S = 102,400, since its emission table is dense); at S = 102,400 this sensor's
   messages span more than a float's range, so both run the exact log-space pass; (b) a
   cold gradient (a fresh estimator: MDP solve, packing, forward-backward; the best of the
   repeats, as for every other timing here, after one traced call, which gives the peak memory
   and is printed too: it also pays for faulting in memory the block sensor's passes freed),
   its forward-backward, and a gradient as a fit takes it
   after its first (theta 1% away: the solve warm-started, the buffers held) with a factored
   sensor (each coordinate misread by one cell 15% of the time, actions exact; 409,600
   observations at S = 102,400, which the frozen path cannot build), and the products floor
   of 4 at the same size, which shows what linear scaling means on this machine's memory
   hierarchy.
4. Forward-backward at S = 10,000 (factored sensor) against its floor: the same sparse
   products, forward and backward, done by scipy alone on arrays of the same shapes; and what
   one block of :func:`irl._blas.one_blas_thread` costs (the fastest of 5 runs of 200 empty
   blocks at a size that sets the limit, 10^5 states x actions), against that
   forward-backward: irl holds BLAS to one thread only from ``S A`` = 10,000 on, where a
   block's cost is nothing beside the work it holds.
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import time
import timeit
import tracemalloc
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy loads; see the docstring

import numpy as np

import irl
from irl import _blas, _numba
from irl.inference import pack_demonstrations, posterior_stats, scratch_held
from irl.solvers import OptimalQSolver, log_boltzmann_policy

sys.path.insert(0, str(Path(__file__).resolve().parent))
from irl_baseline import BaselineMMAPBIRL
from irl_baseline import posterior_stats as baseline_posterior_stats

NUMBA = _numba.available()


#: The clock every timing reads: wall time (the default) or this process's CPU time
#: (``--clock cpu``: the bench is single-threaded, so on a machine shared with other work the
#: CPU time leaves out the time the process waited for a core).
CLOCK = time.perf_counter


def best_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = CLOCK()
        fn()
        times.append(CLOCK() - start)
    return min(times)


# -- 1 ------------------------------------------------------------------------------------

def bench_fit_sorting(repeats: int, n_batches: int = 10) -> None:
    dom = irl.domains.onion_sorting(noise=0.3)
    batches = [dom.sample(12, 20, occlusion=0.2, seed=b)[0] for b in range(n_batches)]
    n_occ = np.mean([d.n_occluded for demos in batches for d in demos])
    kw = {"beta": dom.beta, "prior": dom.prior, "seed": 0}

    def fit_time(cls, **extra):
        # Each batch is timed on its own (best of `repeats`), so a burst of load on a shared
        # machine spoils one timing, not the sum.
        return sum(best_time(lambda d=demos: cls(dom.mdp, dom.observation_model, **extra).fit(d),
                             repeats) for demos in batches) / n_batches

    t_new, t_old = fit_time(irl.MMAPBIRL, **kw), fit_time(BaselineMMAPBIRL, **kw)
    t_em = fit_time(irl.HiddenDataEM)
    if NUMBA:
        irl.MMAPBIRL(dom.mdp, dom.observation_model, backend="numba", **kw).fit(batches[0])
        t_numba = fit_time(irl.MMAPBIRL, backend="numba", **kw)
    same = [np.allclose(irl.MMAPBIRL(dom.mdp, dom.observation_model, **kw).fit(d).theta_,
                        BaselineMMAPBIRL(dom.mdp, dom.observation_model, **kw).fit(d).theta_,
                        atol=1e-8) for d in batches]

    theta = dom.true_theta * 0.7
    grads = {}
    for cls in (irl.MMAPBIRL, BaselineMMAPBIRL):
        est = cls(dom.mdp, dom.observation_model, beta=dom.beta, prior=dom.prior)
        model = est._check_model()
        data = est._prepare(model, batches[0])
        grads[cls] = best_time(lambda e=est, m=model, x=data: e._likelihood_and_gradient(
            m, theta, x), 50 * repeats)
    g_new, g_old = grads[irl.MMAPBIRL], grads[BaselineMMAPBIRL]
    t_naive = best_time(naive_forward(dom.mdp, dom.observation_model, batches[0], theta,
                                      dom.beta), 50 * repeats)
    if NUMBA:
        est = irl.MMAPBIRL(dom.mdp, dom.observation_model, beta=dom.beta, prior=dom.prior,
                           backend="numba")
        model = est._check_model()
        data = est._prepare(model, batches[0])
        g_numba = best_time(lambda: est._likelihood_and_gradient(model, theta, data),
                            50 * repeats)
    print(f"[1] sorting fit, {n_batches} batches of 12 demos x 20 steps, {n_occ:.1f} occluded "
          "each, 30% noise (mean per batch)")
    print(f"    fit:      now {t_new * 1e3:7.1f} ms   frozen cfdfae2 {t_old * 1e3:7.1f} ms   "
          f"speed-up {t_old / t_new:4.1f}x   (same theta_ in {sum(same)}/{n_batches})")
    print(f"    gradient: now {g_new * 1e3:7.3f} ms   frozen cfdfae2 {g_old * 1e3:7.3f} ms   "
          f"speed-up {g_old / g_new:4.1f}x")
    print(f"    a naive numpy forward pass (likelihood alone) {t_naive * 1e3:7.3f} ms: the "
          f"gradient costs {g_new / t_naive:4.2f}x it (target: at most 1.0x)")
    if NUMBA:
        print(f"    fit, numba backend: {t_numba * 1e3:7.1f} ms   speed-up over frozen "
              f"{t_old / t_numba:4.1f}x")
        print(f"    gradient, numba backend: {g_numba * 1e3:7.3f} ms: "
              f"{g_numba / t_naive:4.2f}x the naive forward pass (target: at most 1.0x)")
    print(f"    HiddenDataEM fit {t_em * 1e3:7.1f} ms: MMAP-BIRL is {t_em / t_new:4.1f}x faster")


def naive_forward(mdp, observation_model, demos, theta, beta):
    """The textbook forward pass, batched in numpy, as a yardstick for one gradient: from the
    policy (solved once, outside the timing) and the dense emission table, per step the
    emissions gathered and multiplied in, the message normalized and pushed through the dense
    ``T[s a, s']``; the log-likelihood of the demonstrations (nothing else: no backward pass,
    no gradient)."""
    from irl.demonstrations import pack_observations

    pi = np.exp(log_boltzmann_policy(OptimalQSolver(mdp).q_values(theta), beta))
    E = np.exp(observation_model.log_emissions)  # (observations + 1, S, A): occluded last
    T = mdp._flat.toarray() if hasattr(mdp._flat, "toarray") else np.asarray(mdp._flat)
    obs = pack_observations(demos, observation_model.n_observations)
    p0 = np.exp(mdp.log_initial)
    n = len(obs)

    def forward() -> float:
        alpha = p0[None, :, None] * pi[None] * E[obs[:, 0]]
        ll = np.zeros(n)
        for t in range(1, obs.shape[1]):
            c = alpha.sum(axis=(1, 2))
            ll += np.log(c)
            alpha /= c[:, None, None]
            alpha = (alpha.reshape(n, -1) @ T)[:, :, None] * pi * E[obs[:, t]]
        return float((ll + np.log(alpha.sum(axis=(1, 2)))).sum())

    want = posterior_stats(mdp, np.log(pi), demos, observation_model).log_likelihood.sum()
    if not np.isclose(forward(), want, rtol=1e-10, atol=0.0):
        raise AssertionError("the naive forward pass disagrees with forward-backward")
    return forward


# -- 2 ------------------------------------------------------------------------------------

def bench_gradient_vs_occlusion(repeats: int) -> None:
    dom = irl.domains.onion_sorting(noise=0.3)
    est = irl.MMAPBIRL(dom.mdp, dom.observation_model, beta=dom.beta, prior=dom.prior)
    theta = dom.true_theta * 0.7
    print("[2] one gradient vs occlusion (sorting, 12 demos x 100 steps)")
    base = None
    for occ in (0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6):
        demos, _ = dom.sample(12, 100, occlusion=occ, seed=1)
        t = best_time(lambda d=demos: est.log_posterior_gradient(theta, d), 10 * repeats)
        base = base or t
        print(f"    occlusion {occ:4.0%}: {t * 1e3:7.2f} ms   ratio to 0%: {t / base:.2f}")


# -- 3 and 4 ------------------------------------------------------------------------------

def grid_world(nx: int, ny: int, seed: int = 0):
    """The sparse noisy grid :func:`irl.domains.grid_mdp` (s = x * ny + y, 4 moves, 4
    features), with a factored sensor and a 10 x 10 block state sensor."""
    mdp = irl.domains.grid_mdp(nx, ny, seed=seed)
    n = mdp.n_states
    x, y = np.divmod(np.arange(n), ny)
    factored = irl.factored_observation_model([_neighbour_confusion(nx),
                                               _neighbour_confusion(ny)], n_actions=4)
    block = (x * 10 // nx) * 10 + (y * 10 // ny)
    C = np.full((n, 100), 0.3 / 99)
    C[np.arange(n), block] = 0.7
    return mdp, factored, irl.state_observation_model(C, n_actions=4)


def _neighbour_confusion(n: int, error: float = 0.15) -> np.ndarray:
    C = np.eye(n) * (1.0 - error)
    idx = np.arange(n)
    C[idx[1:], idx[:-1]] += error / 2
    C[idx[:-1], idx[1:]] += error / 2
    C[0, 0] += error / 2
    C[-1, -1] += error / 2
    return C


def grid_demos(mdp, oms, theta, n=10, length=100, occlusion=0.2, seed=0):
    pi = np.exp(log_boltzmann_policy(OptimalQSolver(mdp).q_values(theta), 1.0))
    rng = np.random.default_rng(seed)
    trajs = [irl.demonstrations.sample_trajectory(mdp, pi, length, rng) for _ in range(n)]
    return [[irl.demonstrations.observe(t, om, occlusion, np.random.default_rng(i))
             for i, t in enumerate(trajs)] for om in oms]


def cold_gradient(cls, mdp, om, demos, theta, **kw):
    """A fresh estimator's gradient: MDP solve, packing and forward-backward."""
    return cls(mdp, om, beta=1.0, **kw).log_posterior_gradient(theta, demos)


def warm_gradient(mdp, om, demos, theta, repeats=1, **kw):
    """A gradient as a fit takes it after its first: the best of the estimator's next
    ``repeats``, each at a theta 1% further away (the MDP solve warm-started from the first,
    the demonstrations packed once, the forward-backward buffers held,
    :func:`irl.inference.scratch_held`)."""
    est = irl.MMAPBIRL(mdp, om, beta=1.0, **kw)
    model = est._check_model()
    data = est._prepare(model, demos)
    times = []
    with scratch_held():
        est._likelihood_and_gradient(model, theta, data)
        for k in range(1, repeats + 1):
            start = CLOCK()
            est._likelihood_and_gradient(model, theta * (1 + 0.01 * k), data)
            times.append(CLOCK() - start)
    return min(times)


def fb_time(mdp, om, demos, log_pi, repeats, baseline=False, backend="numpy", warm=True):
    """Best of ``repeats`` forward-backward passes, after one untimed pass (it loads a
    compiled kernel and faults in the pass's memory, for every path alike) unless not
    ``warm`` (the minute-long log-space passes of [3] at S = 102,400, timed once each)."""
    if baseline:
        run = lambda: baseline_posterior_stats(mdp, log_pi, demos, om)  # noqa: E731
    else:
        packed = pack_demonstrations(demos, om)
        run = lambda: posterior_stats(mdp, log_pi, packed, backend=backend)  # noqa: E731
    if warm:
        run()
    return best_time(run, repeats)


def traced(fn):
    """``(seconds, peak traced bytes)`` of one call, or ``(fn(), peak)`` when ``fn`` returns
    its own timing (numpy reports its buffers to tracemalloc)."""
    tracemalloc.start()
    start = CLOCK()
    out = fn()
    seconds = CLOCK() - start
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return (out if isinstance(out, float) else seconds), peak


def products_floor(mdp, n_demos: int, length: int, repeats: int) -> float:
    """The arithmetic floor of forward-backward: the same sparse products, forward and
    backward, done by scipy alone on blocks of the same shapes."""
    P = mdp._flat  # the flat operator T[s * A + a, s'] forward-backward multiplies by
    PT = P.T.tocsr()
    alpha = np.random.default_rng(0).random((mdp.n_states * mdp.n_actions, n_demos))
    g = np.random.default_rng(1).random((mdp.n_states, n_demos))

    def floor():
        for _ in range(length - 1):
            PT @ alpha
        for _ in range(length - 1):
            P @ g

    return best_time(floor, repeats)


def bench_scaling(quick: bool) -> None:
    sizes = [(100, 100), (200, 200)] if quick else [(100, 100), (320, 320)]
    repeats = 1 if quick else 3
    theta = np.array([1.0, -1.0, 0.5, -0.5])
    print("[3] scaling in S: sparse grid T, 10 demos x 100 steps, 20% occluded; a cold "
          "gradient (MDP solve included; best of the repeats, and the first call, traced), its "
          "forward-backward, peak traced memory, and the products floor of [4] at each size")
    rows = []
    mib = 2**20
    for nx, ny in sizes:
        mdp, factored, blocks = grid_world(nx, ny)
        demos_f, demos_b = grid_demos(mdp, (factored, blocks), theta)
        log_pi = log_boltzmann_policy(OptimalQSolver(mdp).q_values(theta), 1.0)
        r = {"S": mdp.n_states}
        warm = mdp.n_states <= 40_000  # beyond, both run the minute-long log-space pass
        r["fb_new"], r["peak_new"] = traced(lambda m=mdp, o=blocks, d=demos_b, p=log_pi, w=warm:
                                            fb_time(m, o, d, p, 1, warm=w))
        r["fb_old"], r["peak_old"] = traced(lambda m=mdp, o=blocks, d=demos_b, p=log_pi, w=warm:
                                            fb_time(m, o, d, p, 1, baseline=True, warm=w))
        del blocks.log_emissions  # the frozen path's dense table
        cold = lambda m=mdp, o=factored, d=demos_f: cold_gradient(  # noqa: E731
            irl.MMAPBIRL, m, o, d, theta)
        r["first_f"], r["peak_f"] = traced(cold)
        r["grad_f"] = best_time(cold, repeats)
        r["fb_f"] = fb_time(mdp, factored, demos_f, log_pi, 1)
        r["warm_f"] = warm_gradient(mdp, factored, demos_f, theta, repeats)
        r["floor"] = products_floor(mdp, len(demos_f), len(demos_f[0]), 1)
        r["solve"], r["solve_lu"] = (best_time(lambda m=mdp, kw=kw: OptimalQSolver(m, **kw)
                                               .solve(theta), repeats)
                                     for kw in ({}, {"krylov_min_states": None}))
        print(f"    S = {r['S']:6d}, block sensor:    forward-backward {r['fb_new']:6.2f} s vs "
              f"frozen {r['fb_old']:6.2f} s ({r['fb_old'] / r['fb_new']:4.1f}x), peak "
              f"{r['peak_new'] / mib:6.0f} MiB vs {r['peak_old'] / mib:6.0f} MiB")
        print(f"    S = {r['S']:6d}, factored sensor: gradient cold {r['grad_f']:6.2f} s (the "
              f"first, traced: {r['first_f']:6.2f} s), "
              f"forward-backward {r['fb_f']:6.2f} s, peak {r['peak_f'] / mib:6.0f} MiB "
              f"(the frozen path cannot build this model); products alone {r['floor']:6.2f} s; "
              f"a gradient within a fit {r['warm_f']:6.2f} s")
        print(f"    S = {r['S']:6d}, a cold MDP solve: {r['solve']:6.2f} s (BiCGSTAB "
              f"evaluations) vs {r['solve_lu']:6.2f} s factored "
              f"({r['solve_lu'] / r['solve']:3.1f}x)")
        if NUMBA:
            # forward-backward first: it loads the compiled kernel, as the gradient above
            # runs after the block sensor's passes
            r["fb_n"] = fb_time(mdp, factored, demos_f, log_pi, 1, backend="numba")
            cold = lambda m=mdp, o=factored, d=demos_f: cold_gradient(  # noqa: E731
                irl.MMAPBIRL, m, o, d, theta, backend="numba")
            r["first_n"], r["peak_n"] = traced(cold)
            r["grad_n"] = best_time(cold, repeats)
            r["warm_n"] = warm_gradient(mdp, factored, demos_f, theta, repeats, backend="numba")
            print(f"    S = {r['S']:6d}, factored sensor, numba backend: gradient cold "
                  f"{r['grad_n']:6.2f} s (the first, traced: {r['first_n']:6.2f} s), "
                  f"forward-backward {r['fb_n']:6.2f} s, peak "
                  f"{r['peak_n'] / mib:6.0f} MiB; a gradient within a fit {r['warm_n']:6.2f} s")
        rows.append(r)
    first, last = rows[0], rows[-1]
    grow = {k: last[k] / first[k] for k in first if k in (
        "grad_f", "first_f", "fb_f", "floor", "grad_n", "first_n", "fb_n", "warm_f", "warm_n",
        "solve", "solve_lu")}
    print(f"    S x{last['S'] / first['S']:.0f} ({first['S']} -> {last['S']}), factored sensor: "
          f"gradient x{grow['grad_f']:.1f} (within a fit x{grow['warm_f']:.1f}), "
          f"forward-backward x{grow['fb_f']:.1f}, the products alone x{grow['floor']:.1f}, a "
          f"cold solve x{grow['solve']:.1f} (factored x{grow['solve_lu']:.1f})" + (
              f"; numba backend: gradient x{grow['grad_n']:.1f} (within a fit "
              f"x{grow['warm_n']:.1f}), forward-backward x{grow['fb_n']:.1f}" if NUMBA else "")
          + "; max RSS of this process "
          f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20:.2f} GiB")
    backends = [("numpy", "grad_f", "first_f", "warm_f")] + (
        [("numba", "grad_n", "first_n", "warm_n")] if NUMBA else [])
    for name, cold, once, warm in backends:
        print(f"    {name}: S x{last['S'] / first['S']:.2f}, a gradient cold x{grow[cold]:.1f}, "
              f"within a fit x{grow[warm]:.1f} (target: at most 12x; the products floor grew "
              f"x{grow['floor']:.1f}; the first cold call, traced, x{grow[once]:.1f}); "
              f"at S = {last['S']}, "
              f"against the products floor ({last['floor']:.2f} s): cold "
              f"{last[cold] / last['floor']:.1f}x, within a fit {last[warm] / last['floor']:.1f}x "
              "(target: at most 6x)")


def bench_floor(repeats: int) -> None:
    mdp, factored, _ = grid_world(100, 100)
    theta = np.array([1.0, -1.0, 0.5, -0.5])
    (demos,) = grid_demos(mdp, (factored,), theta)
    log_pi = log_boltzmann_policy(OptimalQSolver(mdp).q_values(theta), 1.0)
    t_fb = fb_time(mdp, factored, demos, log_pi, repeats)
    if NUMBA:
        t_numba = fb_time(mdp, factored, demos, log_pi, repeats, backend="numba")
    N, L, S = len(demos), len(demos[0]), mdp.n_states
    t_floor = products_floor(mdp, N, L, repeats)
    print(f"[4] forward-backward at S = {S}, {N} demos x {L} steps, factored sensor: "
          f"{t_fb * 1e3:.0f} ms; the same {2 * (L - 1)} sparse products alone "
          f"{t_floor * 1e3:.0f} ms; ratio {t_fb / t_floor:.1f}x")
    if NUMBA:
        print(f"    numba backend: {t_numba * 1e3:.0f} ms; ratio to the products "
              f"{t_numba / t_floor:.1f}x")
    block = blas_block_cost()
    print(f"    one block of irl._blas.one_blas_thread: {block * 1e6:.1f} microseconds (fastest "
          f"of 5 x 200), {block / t_fb:.1e} of this forward-backward")


def blas_block_cost() -> float:
    """Seconds one empty block of :func:`irl._blas.one_blas_thread` costs at a size that sets
    the limit: the fastest of 5 runs of 200 (wall time: threadpoolctl's work)."""
    def block() -> None:
        with _blas.one_blas_thread(10**5):
            pass

    block()  # threadpoolctl's first look at the loaded libraries is not the block's cost
    return min(timeit.repeat(block, number=200, repeat=5)) / 200


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--clock", choices=["wall", "cpu"], default="wall",
                        help="what every timing reads: wall time (default), or this process's "
                             "CPU time, which leaves out waiting for a core on a shared machine")
    parser.add_argument("--scaling-only", action="store_true",
                        help="run section 3 alone (the scaling in S)")
    args = parser.parse_args()
    global CLOCK
    CLOCK = time.process_time if args.clock == "cpu" else time.perf_counter
    repeats = 1 if args.quick else 3
    if args.scaling_only:
        bench_scaling(args.quick)
        return
    bench_fit_sorting(repeats)
    bench_gradient_vs_occlusion(repeats)
    bench_scaling(args.quick)
    bench_floor(repeats)


if __name__ == "__main__":
    main()
