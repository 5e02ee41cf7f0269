"""Uncertainty of sweep results: percentile-bootstrap confidence intervals.

Layouts: ``values[n]``, one number per independent unit (e.g. one batch of demonstrations).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from irl._random import check_random_state

__all__ = ["bootstrap_ci"]


def bootstrap_ci(
    values,
    stat: Callable[..., float] = np.mean,
    *,
    n_resamples: int = 2000,
    confidence: float = 0.95,
    rng: int | np.random.Generator | None = None,
) -> tuple[float, float]:
    """Percentile-bootstrap confidence interval of ``stat(values)``.

    Draws ``n_resamples`` samples of ``n`` values with replacement, computes ``stat`` on each,
    and returns the ``(1 - confidence) / 2`` and ``(1 + confidence) / 2`` quantiles of those
    statistics (Efron's percentile interval). A constant sample gives a point interval; a
    single value gives the point ``(stat(values), stat(values))``.

    Parameters
    ----------
    values : array-like of shape (n,)
        Independent observations, n >= 1, all finite.
    stat : callable, default ``np.mean``
        ``stat(x) -> float`` for ``x`` of shape (n,). If it accepts ``axis`` (as numpy's
        reductions do) it is called once on all resamples, ``stat(X, axis=1)`` with ``X`` of
        shape (n_resamples, n); otherwise once per resample.
    n_resamples : int, default 2000
    confidence : float, default 0.95
        In (0, 1).
    rng : int, numpy Generator or None
        Source of the resampling; pass a seed for a reproducible interval.

    Returns
    -------
    (low, high) : tuple of float
    """
    x = np.asarray(values, dtype=float)
    if x.ndim != 1 or x.size == 0:
        raise ValueError(f"values must be a non-empty 1-D sample; got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError(f"values must be finite; got {x[~np.isfinite(x)][:3].tolist()} among them")
    if isinstance(n_resamples, bool) or not isinstance(n_resamples, int | np.integer) \
            or n_resamples < 1:
        raise ValueError(f"n_resamples must be a positive integer; got {n_resamples!r}")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1); got {confidence!r}")
    if not callable(stat):
        raise TypeError(f"stat must be callable; got {stat!r}")
    gen = check_random_state(rng)
    resamples = x[gen.integers(0, x.size, size=(int(n_resamples), x.size))]
    try:
        stats = np.asarray(stat(resamples, axis=1), dtype=float)
        if stats.shape != (resamples.shape[0],):
            raise TypeError("stat did not reduce along axis 1")
    except TypeError:
        stats = np.array([float(stat(r)) for r in resamples])
    alpha = (1.0 - confidence) / 2.0
    low, high = np.quantile(stats, [alpha, 1.0 - alpha])
    return float(low), float(high)
