"""Uncertainty of results: percentile-bootstrap intervals and Markov-chain diagnostics.

Layouts: ``values[n]``, one number per independent unit (e.g. one batch of demonstrations);
``draws[m, n]``, n draws of each of m chains of one scalar.

The chain diagnostics are those of Vehtari, Gelman, Simpson, Carpenter and Buerkner (2021),
"Rank-normalization, folding, and localization: an improved R-hat", as ArviZ computes them
(``arviz.rhat(method="rank")``, ``arviz.ess(method="bulk")``): the tests check them against
ArviZ.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy import fft, special, stats

from irl._random import check_random_state

__all__ = ["bootstrap_ci", "effective_sample_size", "split_rhat"]


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


def _check_draws(draws) -> np.ndarray:
    x = np.asarray(draws, dtype=float)
    if x.ndim != 2 or x.shape[1] < 4:
        raise ValueError(f"draws must have shape (chains, draws) with at least 4 draws per chain; "
                         f"got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("draws must be finite")
    return x


def _split_chains(x: np.ndarray) -> np.ndarray:
    """Each chain's first and last halves as two chains (the middle draw of an odd length is
    dropped): ``(m, n) -> (2m, n // 2)``."""
    half = x.shape[1] // 2
    return np.concatenate((x[:, :half], x[:, -half:]), axis=0)


def _z_scale(x: np.ndarray) -> np.ndarray:
    """Rank-normalization: pooled ranks (ties averaged) mapped through the normal quantile."""
    ranks = stats.rankdata(x, method="average").reshape(x.shape)
    return special.ndtri((ranks - 0.375) / (x.size + 0.25))


def _rhat(x: np.ndarray) -> float:
    """Gelman-Rubin potential scale reduction of chains ``x[m, n]``."""
    n = x.shape[1]
    between = n * np.var(x.mean(axis=1), ddof=1)
    within = np.mean(np.var(x, axis=1, ddof=1))
    return float(np.sqrt((between / within + n - 1) / n))


def split_rhat(draws) -> float:
    """Rank-normalized split R-hat of one scalar's chains ``draws[m, n]`` (m >= 1).

    The larger of the bulk R-hat (of the rank-normalized split chains) and the tail R-hat (of
    the same, folded about the median). Values near 1 (below 1.01) say the chains agree.
    Constant draws give NaN, as they do in ArviZ.
    """
    x = _split_chains(_check_draws(draws))
    if np.ptp(x) < np.finfo(float).resolution:
        return float("nan")
    folded = np.abs(x - np.median(x))
    return max(_rhat(_z_scale(x)), _rhat(_z_scale(folded)))


def _autocovariance(x: np.ndarray) -> np.ndarray:
    """Biased autocovariance of each chain at lags 0..n-1, by FFT: ``(m, n) -> (m, n)``."""
    n = x.shape[1]
    centred = x - x.mean(axis=1, keepdims=True)
    size = fft.next_fast_len(2 * n)
    spectrum = np.fft.rfft(centred, n=size, axis=1)
    return np.fft.irfft(spectrum * np.conjugate(spectrum), n=size, axis=1)[:, :n] / n


def _ess(x: np.ndarray) -> float:
    """Effective sample size of chains ``x[m, n]``: Geyer's initial monotone sequence over the
    multi-chain autocorrelation estimate (Stan's and ArviZ's estimator)."""
    m, n = x.shape
    if np.ptp(x) < np.finfo(float).resolution:
        return float(x.size)
    acov = _autocovariance(x)
    mean_var = np.mean(acov[:, 0]) * n / (n - 1.0)
    var_plus = mean_var * (n - 1.0) / n
    if m > 1:
        var_plus += np.var(x.mean(axis=1), ddof=1)
    rho = np.zeros(n)
    rho_even, rho_odd = 1.0, 1.0 - (mean_var - np.mean(acov[:, 1])) / var_plus
    rho[0], rho[1] = rho_even, rho_odd
    t = 1
    while t < n - 3 and rho_even + rho_odd > 0.0:  # initial positive sequence
        rho_even = 1.0 - (mean_var - np.mean(acov[:, t + 1])) / var_plus
        rho_odd = 1.0 - (mean_var - np.mean(acov[:, t + 2])) / var_plus
        if rho_even + rho_odd >= 0:
            rho[t + 1], rho[t + 2] = rho_even, rho_odd
        t += 2
    max_t = t - 2
    if rho_even > 0:
        rho[max_t + 1] = rho_even
    t = 1
    while t <= max_t - 2:  # made monotone
        if rho[t + 1] + rho[t + 2] > rho[t - 1] + rho[t]:
            rho[t + 1] = rho[t + 2] = (rho[t - 1] + rho[t]) / 2.0
        t += 2
    tau = -1.0 + 2.0 * np.sum(rho[:max_t + 1]) + np.sum(rho[max_t + 1:max_t + 2])
    tau = max(tau, 1.0 / np.log10(m * n))
    return float(m * n / tau)


def effective_sample_size(draws) -> float:
    """Bulk effective sample size of one scalar's chains ``draws[m, n]``: how many independent
    draws estimate its mean as well (of the rank-normalized split chains)."""
    return _ess(_z_scale(_split_chains(_check_draws(draws))))
