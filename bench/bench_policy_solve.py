"""What a cold MDP solve spends, and what solving its derivatives another way would cost.

    python bench/bench_policy_solve.py     # 10,000 and 102,400 states, about 2 minutes

On the grid of ``bench_irl.py``'s section [3] (``irl.domains.grid_mdp``, gamma 0.99), at
10,000 and 102,400 states, in CPU time on one BLAS thread (as ``bench_irl.py`` runs):

1. one cold ``OptimalQSolver.solve`` under cProfile, its top lines;
2. the derivatives' system ``(I - gamma P_pi) dV = phi_pi`` (4 right-hand sides) of the
   optimal policy, solved as the solver does (SuperLU on a minimum-degree ordering of ``A +
   A^T``, diagonal pivots) and in the other ways measured: the same factorization on an
   ordering kept from before (its numeric part alone), other orderings (COLAMD, minimum
   degree on ``A^T A``, reverse Cuthill-McKee), BiCGSTAB without a preconditioner and with
   an incomplete LU one (SuperLU's ILUTP), each to a relative error of 1e-12 or better
   against the factored solution; the best of 3 for the direct ones.
"""

from __future__ import annotations

import cProfile
import io
import os
import pstats
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy loads, as bench_irl.py

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import reverse_cuthill_mckee

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_irl import grid_world

from irl.solvers import OptimalQSolver

CLOCK = time.process_time
OPTS = {"diag_pivot_thresh": 0.0, "panel_size": 1, "options": {"SymmetricMode": True}}


def best(fn, repeats=3):
    times = []
    for _ in range(repeats):
        start = CLOCK()
        out = fn()
        times.append(CLOCK() - start)
    return min(times), out


def krylov(A, B, X, M=None):
    """BiCGSTAB on each column to a relative residual of 1e-14: (seconds, iterations, worst
    relative error against X)."""
    start, its, err = CLOCK(), [], 0.0
    for k in range(B.shape[1]):
        count = [0]
        x, _ = spla.bicgstab(A, B[:, k], M=M, rtol=1e-14, atol=0.0, maxiter=3000,
                             callback=lambda _x, c=count: c.__setitem__(0, c[0] + 1))
        its.append(count[0])
        err = max(err, np.abs(x - X[:, k]).max() / np.abs(X[:, k]).max())
    return CLOCK() - start, its, err


def main() -> None:
    theta = np.array([1.0, -1.0, 0.5, -0.5])
    for nx in (100, 320):
        mdp, _, _ = grid_world(nx, nx)
        S = mdp.n_states
        OptimalQSolver(mdp).solve(theta * 1.1)  # untimed: first touches
        prof = cProfile.Profile(CLOCK)
        start = CLOCK()
        sol = prof.runcall(OptimalQSolver(mdp).solve, theta)
        out = io.StringIO()
        pstats.Stats(prof, stream=out).sort_stats("tottime").print_stats(6)
        print(f"S = {S}: a cold solve {CLOCK() - start:.3f} s CPU; its top lines:")
        print("\n".join(line for line in out.getvalue().splitlines()
                        if line.strip() and ("{" in line or ".py:" in line)))
        P = mdp.policy_transitions(sol.policy)
        A = (sp.identity(S, format="csc") - mdp.discount * P.tocsc()).tocsc()
        A.sort_indices()
        B = mdp.features[np.arange(S), sol.policy]
        t, lu = best(lambda A=A: spla.splu(A, permc_spec="MMD_AT_PLUS_A", **OPTS))
        X = lu.solve(B)
        print(f"  dV, 4 right-hand sides: the solver's LU {t:.3f} s (fill {lu.nnz:,})")
        order = np.empty(S, dtype=np.intp)
        order[lu.perm_c] = np.arange(S)
        Ap = A[order][:, order].tocsc()
        t, _ = best(lambda Ap=Ap: spla.splu(Ap, permc_spec="NATURAL", **OPTS))
        print(f"  the same LU on an ordering kept from before (numeric part alone) {t:.3f} s")
        for spec in ("COLAMD", "MMD_ATA"):
            t, f = best(lambda A=A, spec=spec: spla.splu(A, permc_spec=spec, **OPTS))
            print(f"  LU on {spec} {t:.3f} s (fill {f.nnz:,})")
        rcm = reverse_cuthill_mckee((A + A.T).tocsr(), symmetric_mode=True)
        Ar = A[rcm][:, rcm].tocsc()
        t, f = best(lambda Ar=Ar: spla.splu(Ar, permc_spec="NATURAL", **OPTS), 1)
        print(f"  LU on reverse Cuthill-McKee {t:.3f} s (fill {f.nnz:,})")
        t, its, err = krylov(A, B, X)
        print(f"  BiCGSTAB, no preconditioner: {t:.3f} s, iterations {its}, error {err:.1e}")
        for drop, fill in ((1e-3, 3), (1e-4, 5)):
            start = CLOCK()
            ilu = spla.spilu(A, drop_tol=drop, fill_factor=fill, permc_spec="MMD_AT_PLUS_A",
                             **OPTS)
            t_ilu = CLOCK() - start
            t, its, err = krylov(A, B, X, spla.LinearOperator(A.shape, ilu.solve))
            print(f"  BiCGSTAB, ILU(drop {drop:g}, fill {fill}): {t_ilu:.3f} s to build + "
                  f"{t:.3f} s, iterations {its}, error {err:.1e}")


if __name__ == "__main__":
    main()
