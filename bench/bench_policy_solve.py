"""What a cold MDP solve spends, and what solving its derivatives another way would cost.

    python bench/bench_policy_solve.py     # 10,000 and 102,400 states, about a minute

On the grid of ``bench_irl.py``'s section [3] (``irl.domains.grid_mdp``, gamma 0.99), at
10,000 and 102,400 states, in CPU time on one BLAS thread (as ``bench_irl.py`` runs):

1. one cold ``OptimalQSolver.solve`` under cProfile, its top lines;
2. the derivatives' system ``(I - gamma P_pi) dV = phi_pi`` (4 right-hand sides) of the
   optimal policy, solved as the solver does (SuperLU on a minimum-degree ordering of ``A +
   A^T``, diagonal pivots) and in the other ways measured: the same factorization on an
   ordering kept from before (its numeric part alone), other orderings (COLAMD, minimum
   degree on ``A^T A``, reverse Cuthill-McKee), BiCGSTAB without a preconditioner and with
   an incomplete LU one (SuperLU's ILUTP), each to a relative error of 1e-12 or better
   against the factored solution; the best of 3 for the direct ones;
3. (issue 40e) the ways measured since: the kept ordering with wider supernodes and panels
   (``relax=16, panel_size=4``); a nested-dissection ordering (the grid's own, by its
   coordinates: the best case of any dissection of this graph, leaves of 16 cells, natural
   order inside them); GCROT(m, k) without a preconditioner, recycling its subspace across
   the 4 right-hand sides; BiCGSTAB preconditioned by the policy's most likely moves (``M = I -
   gamma D``, ``D`` each row's largest entry of ``P_pi`` and its diagonal: a forest of chains
   into cycles, whose LU has 3 entries a column and costs linear time);
4. one value-iteration sweep of the solver against its sparse product alone (the sweeps are
   the largest part of a cold solve at 102,400 states).
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

from irl.solvers import OptimalQSolver, greedy_policy

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
        t, f = best(lambda Ap=Ap: spla.splu(Ap, permc_spec="NATURAL", relax=16,
                                            **{**OPTS, "panel_size": 4}))
        print(f"  the kept ordering, relax=16, panel_size=4 {t:.3f} s (fill {f.nnz:,})")
        nd = grid_dissection(nx, nx, 16)
        And = A[nd][:, nd].tocsc()
        t, f = best(lambda And=And: spla.splu(And, permc_spec="NATURAL", **OPTS))
        print(f"  LU on the grid's nested dissection {t:.3f} s (fill {f.nnz:,})")
        t, its, err = recycled_krylov(A, B, X)
        print(f"  GCROT(30, 10), no preconditioner, recycled: {t:.3f} s, products {its}, "
              f"error {err:.1e}")
        start = CLOCK()
        chain = spla.splu(likeliest_moves(A, P, mdp.discount), permc_spec="MMD_AT_PLUS_A",
                          **OPTS)
        t_chain = CLOCK() - start
        t, its, err = krylov(A, B, X, spla.LinearOperator(A.shape, chain.solve))
        print(f"  BiCGSTAB, preconditioned by I - gamma D (likeliest moves): {t_chain:.3f} s "
              f"to build (fill {chain.nnz:,}) + {t:.3f} s, iterations {its}, error {err:.1e}")
        sweep, product = sweep_times(mdp, theta)
        print(f"  one value-iteration sweep {sweep * 1e3:.3f} ms, its product alone "
              f"{product * 1e3:.3f} ms (the rest {(sweep - product) * 1e3:.3f} ms)")


def grid_dissection(nx: int, ny: int, leaf: int) -> np.ndarray:
    """A nested-dissection order of the ``nx x ny`` grid's cells (``s = x * ny + y``): halve
    the longer side, order both halves, then the separating line; a part of at most ``leaf``
    cells in natural order."""
    parts = []

    def cut(x0, x1, y0, y1):
        if (x1 - x0) * (y1 - y0) <= leaf:
            xs, ys = np.meshgrid(np.arange(x0, x1), np.arange(y0, y1), indexing="ij")
            parts.append((xs * ny + ys).ravel())
        elif x1 - x0 >= y1 - y0:
            m = (x0 + x1) // 2
            cut(x0, m, y0, y1)
            cut(m + 1, x1, y0, y1)
            parts.append(m * ny + np.arange(y0, y1))
        else:
            m = (y0 + y1) // 2
            cut(x0, x1, y0, m)
            cut(x0, x1, m + 1, y1)
            parts.append(np.arange(x0, x1) * ny + m)

    cut(0, nx, 0, ny)
    return np.concatenate(parts)


def likeliest_moves(A, P, gamma) -> sp.csc_matrix:
    """``I - gamma D`` with ``D`` each row's largest entry of ``P`` and its diagonal."""
    coo = P.tocoo()
    order = np.lexsort((-coo.data, coo.row))
    first = np.r_[True, coo.row[order][1:] != coo.row[order][:-1]]
    keep = order[first]
    rows, cols, vals = coo.row[keep], coo.col[keep], coo.data[keep]
    off = rows != cols
    n = A.shape[0]
    diag = P.diagonal()
    D = sp.csr_matrix((np.r_[vals, diag[off]], (np.r_[rows, np.arange(n)[off]],
                                                 np.r_[cols, np.arange(n)[off]])), shape=A.shape)
    M = (sp.identity(n, format="csc") - gamma * D.tocsc()).tocsc()
    M.sort_indices()
    return M


def recycled_krylov(A, B, X):
    """GCROT(30, 10) on each column to a relative residual of 5e-15, its recycled subspace
    kept across the columns: (seconds, products with A, worst relative error against X)."""
    count = [0]

    def matvec(x):
        count[0] += 1
        return A @ x

    op = spla.LinearOperator(A.shape, matvec=matvec)
    start, err, recycled = CLOCK(), 0.0, []
    for k in range(B.shape[1]):
        x, _ = spla.gcrotmk(op, B[:, k], rtol=5e-15, atol=0.0, maxiter=200, m=30, k=10,
                            CU=recycled)
        err = max(err, np.abs(x - X[:, k]).max() / np.abs(X[:, k]).max())
    return CLOCK() - start, count[0], err


def sweep_times(mdp, theta) -> tuple[float, float]:
    """Seconds per sweep of the solver's value iteration (100 sweeps, no early stop, the
    best of 3) and per product ``T V`` alone (the best of 3 runs of 100)."""
    solver = OptimalQSolver(mdp, sweep_patience=None)
    reward = mdp.reward(theta)
    t, _ = best(lambda: solver._value_iteration(reward, reward, greedy_policy(reward), 100))
    values = reward.max(axis=1)
    t_product, _ = best(lambda: [mdp.expect_next(values) for _ in range(100)])
    return t / 100, t_product / 100


if __name__ == "__main__":
    main()
