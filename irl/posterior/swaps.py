"""The posterior of a learner with a ``session_swap``: a mixture over readings of the
demonstrations (which of them were read swapped), each reading weighed by its Laplace
evidence and drawn from by chains, by importance resampling or from its Laplace
approximation.

Layouts: ``theta[n, k]`` samples, ``weights[r]`` the readings' posterior probabilities.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from irl.posterior.importance import IMPORTANCE_PROPOSALS, _importance_draws, _resampled_ess
from irl.posterior.laplace import _draw, _laplace_covariance
from irl.posterior.result import Diagnostics, SwapComponent

logger = logging.getLogger(__name__)


def swap_readings(p_swapped: np.ndarray) -> list[tuple[int, ...]]:
    """The readings of N demonstrations (which of them were read swapped) whose posterior
    weight :func:`sample_posterior` measures: the reading the MAP implies (each demonstration
    swapped where ``p_swapped`` is above 0.5), its complement (the same data explained by the
    reward read backwards), and every reading one demonstration away from either.

    Parameters
    ----------
    p_swapped : array of shape (N,)
        Each demonstration's posterior probability of having been read swapped
        (:meth:`irl.MMAPBIRL.swap_probabilities` at the MAP).

    Returns
    -------
    list of tuple of int
        Each reading as the indices of the demonstrations read swapped, without repeats.
    """
    base = np.asarray(p_swapped) > 0.5
    readings: dict[tuple[int, ...], None] = {}
    for root in (base, ~base):
        readings[tuple(int(i) for i in np.flatnonzero(root))] = None
        for i in range(base.size):
            z = root.copy()
            z[i] = ~z[i]
            readings[tuple(int(j) for j in np.flatnonzero(z))] = None
    return list(readings)



#: The readings of least weight whose draws come from their Laplace approximation, not from
#: chains of their own: as many as together hold at most this share of the posterior's
#: weight (with ``method="mcmc"``; see :func:`_draw_swap_readings`).
LAPLACE_SHARE = 0.05


def _draw_swap_readings(estimator, demos, map_theta, prior_precision, n_samples, draw):
    """The posterior of a learner with a ``session_swap``: a mixture over readings of the
    demonstrations (:func:`swap_readings`), each reading's reward posterior drawn as without a
    swap and weighted by its prior probability times its Laplace evidence.

    Each reading gives its share of the samples (:func:`_apportion`). With ``"mcmc"``, a
    reading's chains first run ``n_draws`` scaled by its share, so that its samples are
    thinned from as many draws each as the plain posterior's, and are extended by as many at
    a time while they disagree (R-hat), up to ``max_draws`` as without a swap and, for a
    reading other than the heaviest, while their gradients number fewer than the heaviest
    reading's chains took: no lighter reading costs more than the heaviest, which costs
    about what the plain posterior does (a reading's error enters the mixture times its
    weight); a reading that holds every sample is drawn exactly as without a swap. The readings
    of least weight, together at most :data:`LAPLACE_SHARE` of it, are drawn from their Laplace
    approximation (the Gaussian whose evidence gave their weight) instead of by chains of
    their own, each of which would cost a warm-up as long as the main reading's. The heaviest
    reading's chains run first; every other reading that would get chains is first drawn by
    importance resampling from its Laplace approximation (:func:`_importance_draws`,
    :data:`IMPORTANCE_PROPOSALS` proposals a sample, the proposal adapted up to
    :data:`IMPORTANCE_ADAPTATIONS` times where its weights fail), tried where its evaluations,
    all its rounds' together, number fewer than the heaviest reading's chain gradients and kept
    where the importance weights' effective sample size reaches the reading's samples and
    their Pareto shape ``k`` is below the threshold of Pareto-smoothed importance sampling;
    else it gets chains, in the readings' order. Then the Gaussian draws."""
    swap = estimator.session_swap
    plain = {**estimator.get_params(), "session_swap": None}
    readings = swap_readings(estimator.swap_probabilities(map_theta, demos))
    K, N = map_theta.size, len(demos)
    fitted = []
    for z in readings:
        read = [swap.apply(d) if i in z else d for i, d in enumerate(demos)]
        est = type(estimator)(**plain).fit(read)
        logger.info("reading swapped %s fitted: %d evaluations, log posterior %.6f", list(z),
                    len(est.history_), est.log_posterior_)
        # the value with its gradient (chains, Hessian) and alone (importance proposals), on
        # one preparation of the demonstrations read so
        value_and_grad, value = est._objectives(est._check_model(), read)
        theta_z = np.asarray(est.theta_, float)
        laplace = _laplace_covariance(value_and_grad, theta_z, prior_precision, draw["step"])
        log_weight = (len(z) * np.log(swap.rate) + (N - len(z)) * np.log1p(-swap.rate)
                      + est.log_posterior_ + 0.5 * K * np.log(2 * np.pi)
                      + 0.5 * np.linalg.slogdet(laplace[0])[1])
        fitted.append((z, theta_z, (value_and_grad, value), laplace, float(log_weight)))
    logs = np.array([f[-1] for f in fitted])
    weights = np.exp(logs - logs.max())
    weights /= weights.sum()
    counts = _apportion(weights, n_samples)
    by_laplace = np.zeros(len(readings), dtype=bool)
    if draw["method"] == "mcmc":
        order = np.argsort(weights, kind="stable")
        by_laplace[order[np.cumsum(weights[order]) <= LAPLACE_SHARE]] = True
    thetas: list[np.ndarray | None] = [None] * len(readings)
    chains: list[Diagnostics] = []
    gaussian: list[Diagnostics] = []
    heaviest = int(np.argmax(weights))  # first: its chains' cost decides for the others
    chain_cost = None  # the gradients of the heaviest reading's chains
    for i in [*sorted(np.flatnonzero(~by_laplace), key=lambda j: j != heaviest),
              *np.flatnonzero(by_laplace)]:
        n = int(counts[i])
        if not n:
            continue
        _, theta_z, (value_and_grad, value), laplace, _ = fitted[i]
        resampled, weighed = None, 0
        if draw["method"] == "mcmc" and not by_laplace[i] and i != heaviest \
                and chain_cost is not None and IMPORTANCE_PROPOSALS * n < chain_cost:
            # cheaper than chains of its own: importance resampling from its Laplace
            # approximation (adapted while still cheaper), where the weights' ESS reaches its
            # samples
            resampled, ess, weighed, k = _importance_draws(
                value, theta_z, laplace[0], n, IMPORTANCE_PROPOSALS * n, draw["rng"],
                budget=chain_cost)
            logger.info("reading swapped %s: importance weights' ESS %.0f, Pareto k %.2f (%d "
                        "proposals weighed in all) for %d samples%s",
                        list(fitted[i][0]), ess, k, weighed, n,
                        "" if resampled is not None else ": chains instead")
        if resampled is not None:  # counted as the Gaussian draws are: sizes and costs
            thetas[i] = resampled
            gaussian.append(Diagnostics(
                r_hat=np.full(K, np.nan), ess=np.full(K, _resampled_ess(ess, n)),
                acceptance=1.0,
                n_chains=1, n_warmup=0, n_draws=n, n_divergent=0,
                n_gradients=laplace[2] + weighed, hessian_clipped=laplace[1]))
            continue
        if by_laplace[i]:
            opts = {**draw, "method": "laplace"}
        else:  # the first draws per chain scaled by the reading's share, extended by as
            # many at a time while the chains disagree, up to max_draws as without a swap
            scaled = max(-(-draw["n_draws"] * n // n_samples), 4)
            opts = {**draw, "n_draws": scaled, "max_draws": max(scaled, draw["max_draws"]),
                    "max_gradients": chain_cost}  # None for the heaviest
        thetas[i], diag, _ = _draw(value_and_grad, theta_z, prior_precision, n,
                                   laplace=laplace, **opts)
        diag = replace(diag, n_gradients=diag.n_gradients + weighed)  # a proposal that failed
        if i == heaviest and not by_laplace[i]:
            chain_cost = diag.n_gradients - laplace[2]
        logger.info("reading swapped %s (weight %.3f, %d samples): %s, %d gradients, %d "
                    "draws a chain, max R-hat %.3f", list(fitted[i][0]), weights[i], n,
                    "chains" if opts["method"] == "mcmc" else "Laplace", diag.n_gradients,
                    diag.n_draws,
                    diag.max_r_hat())
        diag = replace(diag, ess=np.minimum(diag.ess, n))  # what it gave, at most
        (gaussian if by_laplace[i] and draw["method"] == "mcmc" else chains).append(diag)
    components = tuple(SwapComponent(swapped=z, weight=float(w), log_weight=f[-1],
                                     n_samples=int(n))
                       for (z, *f), w, n in zip(fitted, weights, counts, strict=True))
    logger.info("posterior over %d readings of %d demonstrations: %s%s", len(readings), N,
                ", ".join(f"swapped {list(c.swapped)} {c.weight:.3f}"
                          for c in sorted(components, key=lambda c: -c.weight)[:4]),
                f"; {int(counts[by_laplace].sum())} samples of readings of weight "
                f"{weights[by_laplace].sum():.3f} in all drawn from their Laplace "
                "approximation" if counts[by_laplace].sum() else "")
    return (np.vstack([t for t in thetas if t is not None]), _combined(chains, gaussian),
            components)


def _apportion(weights: np.ndarray, n: int) -> np.ndarray:
    """``n`` split by ``weights`` into integers (largest remainders, ties to the first)."""
    exact = weights * n
    counts = np.floor(exact).astype(int)
    order = np.argsort(-(exact - counts), kind="stable")
    counts[order[:n - counts.sum()]] += 1
    return counts


def _combined(diags: list[Diagnostics], gaussian: Sequence[Diagnostics] = ()) -> Diagnostics:
    """The diagnostics of several components' draws: the worst R-hat of each weight, summed
    sizes (each component's ESS at most the samples it gave) and costs (the chains' and the
    Hessians' gradients; not the fits of the readings), the mean acceptance. ``gaussian``: the
    diagnostics of readings drawn from their Laplace approximation beside chains (``diags``),
    which count in the sizes and costs only."""
    every = [*diags, *gaussian]
    return Diagnostics(
        r_hat=np.max([d.r_hat for d in diags], axis=0), ess=np.sum([d.ess for d in every], axis=0),
        acceptance=float(np.mean([d.acceptance for d in diags])), n_chains=diags[0].n_chains,
        n_warmup=diags[0].n_warmup, n_draws=max(d.n_draws for d in diags),
        n_divergent=sum(d.n_divergent for d in diags),
        n_gradients=sum(d.n_gradients for d in every),
        hessian_clipped=sum(d.hessian_clipped for d in every))
