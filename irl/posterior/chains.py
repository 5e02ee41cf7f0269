"""HMC chains on the exact gradient of the log posterior, from the ``mici`` library (imported
when first used).

Layouts: ``z[chains, draws, k]`` in whitened coordinates, ``theta = mean + chol z``.
"""

from __future__ import annotations

import logging

import numpy as np

from irl.stats import split_rhat

logger = logging.getLogger(__name__)


def _run_chains(value_and_grad, mean, chol, *, n_chains, n_warmup, n_draws, max_draws, rng,
                max_gradients=None):
    """HMC chains (mici's dynamic multinomial sampler) on ``z`` with ``theta = mean + chol z``,
    extended by ``n_draws`` at a time, at the warm-up's step size, while the split R-hat of a
    weight exceeds 1.01, fewer than ``max_draws`` draws a chain are held and (where given)
    fewer than ``max_gradients`` gradients have been taken. Returns
    ``(theta[chains, draws, K], statistics of every main draw, n_gradients)``."""
    import mici

    counter = [0]

    def neg_log_density(z):
        return -value_and_grad(mean + chol @ z)[0]

    def grad_neg_log_density(z):
        counter[0] += 1
        value, grad = value_and_grad(mean + chol @ z)
        return -(chol.T @ grad), -value

    K = mean.size
    starts = [rng.standard_normal(K) for _ in range(n_chains)]
    states, traces, stats = mici.sample_hmc_chains(
        n_warmup, n_draws, starts, neg_log_density, grad_neg_log_dens=grad_neg_log_density,
        seed=rng, display_progress=False)
    z = np.asarray(traces["pos"], dtype=float)  # (chains, draws, K)
    stats = {k: np.asarray(stats[k]) for k in ("accept_stat", "diverging", "step_size")}
    step_size = float(np.mean(stats["step_size"][:, -1]))
    while (z.shape[1] + n_draws <= max_draws
           and (max_gradients is None or counter[0] < max_gradients)
           and max(split_rhat(z[:, :, k]) for k in range(K)) > 1.01):
        logger.info("extending the chains by %d draws (max R-hat above 1.01)", n_draws)
        states, more, more_stats = mici.sample_hmc_chains(
            0, n_draws, states, neg_log_density, grad_neg_log_dens=grad_neg_log_density,
            seed=rng, display_progress=False, integrator_kwargs={"step_size": step_size})
        z = np.concatenate([z, np.asarray(more["pos"], dtype=float)], axis=1)
        stats = {k: np.concatenate([v, np.asarray(more_stats[k])], axis=1)
                 for k, v in stats.items()}
    return mean + z @ chol.T, stats, counter[0]
