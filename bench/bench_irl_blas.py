"""One cold MMAP-BIRL gradient with BLAS on its default thread pool against one thread.

    python bench/bench_irl_blas.py            # 10,000 and 102,400 states, 2 pairs each
    python bench/bench_irl_blas.py --pairs 3

Unlike ``bench/bench_irl.py``, this bench leaves OpenBLAS's thread pool as the process gets it
(one thread per core, unless ``OPENBLAS_NUM_THREADS`` says otherwise), as ``onionsort learn``
does. It times one cold gradient (a fresh estimator: MDP solve, packing, forward-backward) on
the grid of ``bench_irl.py``'s section [3] with its factored sensor, with irl's limit to one
BLAS thread (:mod:`irl._blas`) and without it (its threshold raised past any array: the code
before the limit), alternating pair by pair on both backends, and prints the medians of CPU
and wall time and the growth from 10,000 to 102,400 states.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

import irl
from irl import _blas, _numba

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_irl import grid_demos, grid_world


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--pairs", type=int, default=2)
    args = parser.parse_args()
    theta = np.array([1.0, -1.0, 0.5, -0.5])
    backends = ["numpy"] + (["numba"] if _numba.available() else [])
    limit = _blas.MIN_ELEMENTS
    med = {}
    for nx in (100, 320):
        mdp, factored, _ = grid_world(nx, nx)
        (demos,) = grid_demos(mdp, (factored,), theta)
        for backend in backends:
            # untimed: compiles or loads the kernel, faults in the first memory
            irl.MMAPBIRL(mdp, factored, beta=1.0, backend=backend).log_posterior_gradient(
                theta * 1.1, demos)
            times = {"one": [], "pool": []}
            for pair in range(args.pairs):  # which goes first alternates pair by pair
                for name in (("pool", "one") if pair % 2 == 0 else ("one", "pool")):
                    _blas.MIN_ELEMENTS = limit if name == "one" else 10**15
                    cpu, wall = time.process_time(), time.perf_counter()
                    irl.MMAPBIRL(mdp, factored, beta=1.0, backend=backend) \
                        .log_posterior_gradient(theta, demos)
                    times[name].append((time.process_time() - cpu, time.perf_counter() - wall))
            _blas.MIN_ELEMENTS = limit
            for name, got in times.items():
                cpu, wall = np.median(np.array(got), axis=0)
                med[mdp.n_states, backend, name] = cpu, wall
                print(f"S = {mdp.n_states:6d}, {backend}, BLAS "
                      f"{'one thread' if name == 'one' else 'default pool'}: a cold gradient "
                      f"{cpu:6.2f} s CPU, {wall:6.2f} s wall (median of {args.pairs})",
                      flush=True)
    for backend in backends:
        for name in ("pool", "one"):
            lo, hi = med[10_000, backend, name], med[102_400, backend, name]
            print(f"{backend}, BLAS {'one thread' if name == 'one' else 'default pool'}: S x10.24,"
                  f" a cold gradient x{hi[0] / lo[0]:.1f} CPU, x{hi[1] / lo[1]:.1f} wall")


if __name__ == "__main__":
    main()
