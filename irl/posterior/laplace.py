"""The Laplace approximation at a mode of the exact log posterior, and the draws round it:
from the Gaussian itself (``"laplace"``), or by HMC chains in the coordinates it whitens
(``"mcmc"``, :mod:`irl.posterior.chains`).

Layouts: ``theta[n, k]`` draws, ``covariance[k, k]``.
"""

from __future__ import annotations

import numpy as np

from irl.posterior.chains import _run_chains
from irl.posterior.result import Diagnostics
from irl.stats import effective_sample_size, split_rhat


def _laplace_covariance(value_and_grad, theta: np.ndarray, prior_precision: np.ndarray,
                        step: float) -> tuple[np.ndarray, int, int]:
    """Covariance of the Laplace approximation at ``theta`` by central differences of the
    exact gradient; eigenvalues of the precision below the prior's are raised to it. Returns
    ``(covariance, n_clipped, n_gradients)``."""
    K = theta.size
    H = np.empty((K, K))
    for k in range(K):
        h = step * max(1.0, abs(theta[k]))
        e = np.zeros(K)
        e[k] = h
        H[:, k] = (value_and_grad(theta + e)[1] - value_and_grad(theta - e)[1]) / (2 * h)
    precision = -(H + H.T) / 2
    vals, vecs = np.linalg.eigh(precision)
    floor = float(np.min(prior_precision))
    clipped = int(np.sum(vals < floor))
    vals = np.maximum(vals, floor)
    return (vecs / vals) @ vecs.T, clipped, 2 * K



def _draw(value_and_grad, map_theta, prior_precision, n_samples, *, method, rng, n_chains,
          n_warmup, n_draws, max_draws, step, laplace=None, max_gradients=None
          ) -> tuple[np.ndarray, Diagnostics, np.ndarray]:
    """``n_samples`` draws round the mode ``map_theta`` of ``value_and_grad``: ``(theta,
    diagnostics, Laplace covariance)``. ``laplace``: the mode's
    :func:`_laplace_covariance`, when already computed; ``max_gradients``: the chains are not
    extended past it (:func:`_run_chains`)."""
    cov, clipped, n_grad = laplace or _laplace_covariance(value_and_grad, map_theta,
                                                          prior_precision, step)
    chol = np.linalg.cholesky(cov)
    if method == "laplace":
        theta = map_theta + rng.standard_normal((n_samples, map_theta.size)) @ chol.T
        return theta, Diagnostics(
            r_hat=np.full(map_theta.size, np.nan), ess=np.full(map_theta.size, n_samples),
            acceptance=1.0, n_chains=1, n_warmup=0, n_draws=n_samples, n_divergent=0,
            n_gradients=n_grad, hessian_clipped=clipped), cov
    chains, stats, n_chain_grad = _run_chains(
        value_and_grad, map_theta, chol, n_chains=n_chains, n_warmup=n_warmup,
        n_draws=n_draws, max_draws=max_draws, rng=rng, max_gradients=max_gradients)
    diagnostics = Diagnostics(
        r_hat=np.array([split_rhat(chains[:, :, k]) for k in range(map_theta.size)]),
        ess=np.array([effective_sample_size(chains[:, :, k]) for k in range(map_theta.size)]),
        acceptance=float(np.mean(stats["accept_stat"])), n_chains=n_chains,
        n_warmup=n_warmup, n_draws=chains.shape[1],
        n_divergent=int(np.sum(stats["diverging"])),
        n_gradients=n_grad + n_chain_grad, hessian_clipped=clipped)
    pooled = chains.reshape(-1, map_theta.size)
    keep = np.linspace(0, pooled.shape[0] - 1, n_samples).round().astype(int)
    return pooled[keep], diagnostics, cov
