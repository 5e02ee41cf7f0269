"""Uncertainty of results: percentile-bootstrap intervals and Markov-chain diagnostics.

Layouts: ``values[n]``, one number per independent unit (e.g. one batch of demonstrations);
``draws[m, n]``, n draws of each of m chains of one scalar.

The chain diagnostics are those of Vehtari, Gelman, Simpson, Carpenter and Buerkner (2021),
"Rank-normalization, folding, and localization: an improved R-hat", as ArviZ computes them
(``arviz.rhat(method="rank")``, ``arviz.ess(method="bulk")``): the tests check them against
ArviZ. Importance weights ``log_w[S]`` are judged by Pareto-smoothed importance sampling
(Vehtari, Simpson, Gelman, Yao and Gabry 2024, "Pareto smoothed importance sampling", JMLR
25(72)), as ``arviz.psislw`` computes it (the tests check it against ArviZ, which is a
development dependency only).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy import fft, special, stats

from irl._random import check_random_state
from irl._validation import check_int

__all__ = ["PSIS_KHAT_MAX", "bootstrap_ci", "effective_sample_size", "pareto_smoothed",
           "psis_khat_threshold", "split_rhat"]


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

    Parameters
    ----------
    draws : array of shape (m, n)
        ``n`` draws of each of ``m`` chains.

    Returns
    -------
    float
        R-hat, >= 1 up to rounding, or NaN for constant draws.
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
    draws estimate its mean as well (of the rank-normalized split chains).

    Parameters
    ----------
    draws : array of shape (m, n)
        ``n`` draws of each of ``m`` chains.

    Returns
    -------
    float
        The bulk ESS, as ``arviz.ess(method="bulk")`` computes it.
    """
    return _ess(_z_scale(_split_chains(_check_draws(draws))))


#: The Pareto shape ``k`` above which no practical number of importance draws gives a
#: reliable estimate (Vehtari et al. 2024): :func:`psis_khat_threshold`'s cap.
PSIS_KHAT_MAX = 0.7


def psis_khat_threshold(n_draws: int) -> float:
    """The largest Pareto shape ``k`` for which ``n_draws`` importance draws give a reliable
    estimate: ``min(1 - 1 / log10(S), 0.7)`` (Vehtari et al. 2024: below it the estimate's error
    falls as for a finite variance within ``S`` draws; above 0.7 no practical ``S``
    suffices). At most 0 for fewer than 10 draws, which no ``k`` passes.

    Parameters
    ----------
    n_draws : int
        ``S``, the importance draws, >= 1.

    Returns
    -------
    float
        The threshold on ``k`` (``-inf`` for one draw).
    """
    S = check_int(n_draws, "n_draws", low=1)
    return min(1.0 - 1.0 / np.log10(S), PSIS_KHAT_MAX) if S > 1 else float("-inf")


def _gpd_fit(x: np.ndarray) -> tuple[float, float]:
    """Shape ``k`` and scale ``sigma`` of a generalized Pareto fitted to the sorted positive
    exceedances ``x[M]`` by Zhang and Stephens' (2009) empirical Bayes estimate, with the
    weakly informative prior on ``k`` (10 pseudo-observations at 0.5) of Vehtari et al.
    (2024), as ``arviz``'s ``_gpdfit``."""
    n = x.size
    m = 30 + int(np.sqrt(n))
    b = 1.0 - np.sqrt(m / (np.arange(1, m + 1, dtype=float) - 0.5))
    b /= 3.0 * x[int(n / 4 + 0.5) - 1]
    b += 1.0 / x[-1]
    k = np.mean(np.log1p(-b[:, None] * x), axis=1)
    log_lik = n * (np.log(-b / k) - k - 1.0)
    w = np.exp(log_lik - special.logsumexp(log_lik))  # 1 / sum_j exp(L_j - L_i), no overflow
    keep = w >= 10 * np.finfo(float).eps
    b, w = b[keep], w[keep] / w[keep].sum()
    b_post = float(b @ w)
    k_post = float(np.mean(np.log1p(-b_post * x)))
    sigma = -k_post / b_post
    return (n * k_post + 10 * 0.5) / (n + 10), sigma


def pareto_smoothed(log_weights) -> tuple[np.ndarray, float]:
    """Pareto-smoothed importance sampling of independent draws' weights ``log_w[S]`` (up to a
    constant; ``-inf`` or NaN: weight 0): a generalized Pareto fitted (:func:`_gpd_fit`) to the
    ``M = ceil(min(S / 5, 3 sqrt(S)))`` largest weights less the next one, whose shape ``k``
    says how heavy the weights' tail is, and those weights replaced by the fit's expected
    order statistics, truncated at the largest raw weight (Vehtari et al. 2024, with a
    relative efficiency of 1).

    Parameters
    ----------
    log_weights : array of shape (S,)
        The draws' log importance weights, at least one finite.

    Returns
    -------
    log_w_smoothed : ndarray of shape (S,)
        The smoothed log weights, normalized to sum to 1 in exp.
    k : float
        The fitted Pareto shape; ``inf`` where fewer than 5 weights exceed the cutoff (no fit
        possible), the weights then only normalized. Compare it with
        :func:`psis_khat_threshold`.
    """
    x = np.asarray(log_weights, dtype=float).copy()
    if x.ndim != 1 or not x.size:
        raise ValueError(f"log_weights must be a non-empty 1-D array; got shape {x.shape}")
    x[np.isnan(x)] = -np.inf
    if not np.isfinite(top := x.max()):
        raise ValueError("log_weights must hold a finite weight; got none")
    x -= top
    S = x.size
    order = np.argsort(x)
    cutoff = max(x[order[-int(np.ceil(min(S / 5.0, 3.0 * np.sqrt(S)))) - 1]],
                 np.log(np.finfo(float).tiny))
    tail = np.flatnonzero(x > cutoff)
    k = float("inf")
    if tail.size > 4:
        tail = tail[np.argsort(x[tail])]
        k, sigma = _gpd_fit(np.exp(x[tail]) - np.exp(cutoff))
        if np.isfinite(k) and sigma > 0:
            p = np.arange(0.5, tail.size) / tail.size
            q = -np.log1p(-p) if abs(k) < np.finfo(float).eps \
                else np.expm1(-k * np.log1p(-p)) / k
            x[tail] = np.minimum(np.log(sigma * q + np.exp(cutoff)), 0.0)
    return x - special.logsumexp(x), k
