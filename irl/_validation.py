"""Input checks shared by the public constructors (one error format: name, rule, value)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from irl._random import check_random_state

__all__ = ["check_probability_rows", "check_random_state"]

ROW_SUM_TOL = 1e-6


def check_probability_rows(probs, name: str, tol: float = ROW_SUM_TOL) -> None:
    """Raise ``ValueError`` unless every row of ``probs`` (last axis) is a distribution.

    ``probs`` is a dense array whose last axis is the outcome, or a 2-D sparse matrix.
    The message names the argument and the first offending row.
    """
    if sp.issparse(probs):
        data = probs.data
        if data.size and not np.all(np.isfinite(data)):
            raise ValueError(f"{name} must be finite; found NaN or inf")
        if data.size and data.min() < 0:
            raise ValueError(f"{name} must be non-negative; found {data.min():.6g}")
        sums = np.asarray(probs.sum(axis=1)).ravel()
        shape = (probs.shape[0],)
    else:
        probs = np.asarray(probs)
        if not np.all(np.isfinite(probs)):
            raise ValueError(f"{name} must be finite; found NaN or inf")
        if probs.size and probs.min() < 0:
            idx = np.unravel_index(np.argmin(probs), probs.shape)
            raise ValueError(
                f"{name} must be non-negative; {name}[{', '.join(map(str, idx))}] = "
                f"{probs[idx]:.6g}"
            )
        sums = probs.sum(axis=-1)
        shape = sums.shape
    bad = np.flatnonzero(np.abs(sums - 1.0).ravel() > tol)
    if bad.size:
        idx = np.unravel_index(bad[0], shape)
        raise ValueError(
            f"{name} rows must sum to 1 over the last axis; row {tuple(int(i) for i in idx)} "
            f"sums to {sums.ravel()[bad[0]]:.6g} ({bad.size} bad rows)"
        )
