"""Importance resampling of a reading's posterior from its Laplace approximation, tested by
Kish's effective sample size and the Pareto shape of Pareto-smoothed importance sampling
(PSIS), with the proposal adapted where it misses.

Layouts: ``theta[m, k]`` proposals, ``log_w[m]`` their log importance weights.
"""

from __future__ import annotations

import logging

import numpy as np

from irl.stats import PSIS_KHAT_MAX, pareto_smoothed, psis_khat_threshold

logger = logging.getLogger(__name__)

#: Proposals per sample of a reading drawn by importance resampling (see
#: :func:`_importance_draws`).
IMPORTANCE_PROPOSALS = 20

#: Degrees of freedom of the Student-t proposal round a reading's mode: heavier tails than the
#: Laplace Gaussian, so that the importance weights stay bounded where the posterior's tails
#: are heavier than a Gaussian's.
_PROPOSAL_DOF = 5.0

#: Rounds of adaptation, at most, of a reading's importance proposal (population Monte Carlo)
#: where its pilot, or all its proposals, fall short (see :func:`_importance_draws`). The first
#: round moves the proposal to where the weight lies, from weights whose effective sample size
#: may be a handful (the covariance then stays mostly the Laplace one); the next ones
#: re-estimate centre and covariance from draws that overlap the posterior more each time. A
#: posterior far from its Laplace approximation can take several: on a reading of 62 samples
#: of a `hard` demo (seed 7802, docs/performance.md) two rounds left the Pareto k at 0.69-0.86
#: and four brought it to 0.41. What bounds the rounds is their cost: each costs at most the
#: proposals again, and is begun only where the attempt would still cost fewer evaluations
#: than chains; this cap only bounds the variates drawn beforehand.
IMPORTANCE_ADAPTATIONS = 8


def _resampled_ess(weights_ess: float, n: int) -> float:
    """The effective sample size of ``n`` draws resampled from importance weights whose own
    (Kish's) effective sample size is ``weights_ess``: ``1 / (1 / n + 1 / weights_ess)``, as a
    mean over the resampled draws has the weights' variance plus the resampling's. Below both
    ``n`` and ``weights_ess`` (about ``n / 2`` where they are equal)."""
    if n < 1 or not weights_ess > 0:
        raise ValueError(f"n must be >= 1 and weights_ess > 0; got {n} and {weights_ess}")
    return 1.0 / (1.0 / n + 1.0 / weights_ess)


def _adapted_proposal(theta: np.ndarray, w: np.ndarray, ess: float, cov: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """The centre and scale matrix of the next proposal from weighted proposals ``theta[m, K]``
    (weights ``w`` summing to 1, Kish's ESS ``ess``): their weighted mean, and their weighted
    covariance (unbiased for reliability weights, ``/ (1 - sum w^2)``) shrunk toward the
    Laplace covariance ``cov`` as the mean of an inverse-Wishart posterior whose prior holds
    ``K`` pseudo-observations of ``cov``: ``(ess S + K cov) / (ess + K)``. Positive definite
    as ``cov`` is; mostly ``cov`` while the ESS is below the dimension, whose
    covariance so few points cannot estimate."""
    K = theta.shape[1]
    mean = w @ theta
    d = theta - mean
    spread = np.zeros((K, K))
    if (denom := 1.0 - float(w @ w)) > 0:
        spread = (w[:, None] * d).T @ d / denom
    shape = (ess * spread + K * cov) / (ess + K)
    return mean, (shape + shape.T) / 2


def _importance_draws(log_density, mode, cov, n, n_proposals, rng, budget=None):
    """``n`` draws from the density ``exp(log_density(theta))`` by importance
    resampling from a Student-t of ``_PROPOSAL_DOF`` degrees of freedom, first round ``mode``
    with scale matrix ``cov`` (its Laplace approximation): ``n_proposals`` proposals, weighed by
    density over proposal and resampled systematically, where their weights pass two tests:
    their effective sample size (Kish's, ``1 / sum w^2``) reaches ``n``, and the Pareto shape
    ``k`` of their largest weights (:func:`irl.stats.pareto_smoothed`) is below the threshold
    of Pareto-smoothed importance sampling for ``n_proposals`` draws,
    ``min(1 - 1 / log10(S), 0.7)`` (:func:`irl.stats.psis_khat_threshold`; Vehtari et al.
    2024): Kish's ESS can pass weights whose tail is too heavy for their mean to be trusted,
    where the proposal misses part of the density, and ``k`` sees that tail. The resampling
    then draws from the Pareto-smoothed weights (the largest replaced by the fitted Pareto's
    expected order statistics), whose noise in the few weights that decide which proposals are
    repeated is lower, at a bias the test on ``k`` keeps small. Where a whole set fails on
    ``k`` alone, below 0.7, the same proposal first draws more, up to the fewest proposals
    whose threshold is above that ``k`` (:func:`_psis_draws_for`; at most
    :data:`_PSIS_CAP_DRAWS` in all), and the grown set is tested again: the remedy of
    Vehtari et al. for ``1 - 1 / log10(S) <= k < 0.7``, where the estimate is reliable with
    more draws. A pilot of a quarter of the
    proposals comes first, and the rest are weighed only where its ESS, times 4, reaches ``n``
    (its ``k`` is logged, not tested: from a quarter of the draws the fit of the tail is
    noisier, and the threshold is set for the set that is resampled). Where the pilot or all
    the proposals fall short, the proposal is adapted (population Monte Carlo, Cappe et
    al. 2004): the next is centred on the weighted mean of the draws just weighed, with their
    weighted covariance shrunk toward ``cov`` (:func:`_adapted_proposal`), and draws
    ``n_proposals`` of its own in the same way, up to :data:`IMPORTANCE_ADAPTATIONS` times and
    while the evaluations stay below ``budget`` (a round is begun only where all its proposals
    would keep them below it; None: no limit). Only the last proposal's draws are weighed for
    the resampling (a proposal built from earlier draws is valid for the draws made after it).
    Each pilot's and each whole set's ESS and ``k`` are logged.

    Returns ``(theta[n, K], ess, n_weighed, k)`` (``ess`` and ``k`` of the raw weights;
    ``n_weighed`` the evaluations of the density in all rounds), or ``(None, ess, n_weighed,
    k)`` where the last proposal tried falls short too (the ESS returned is then its pilot's,
    times 4, or its weights', and ``k`` that of the weights it was from): it then misses too
    much of the posterior to stand for chains. The generator's draws are the same whatever the
    outcome (every proposal's variates, its extension's included, are drawn first)."""
    K = mode.size
    nu = _PROPOSAL_DOF
    pilot = max(1, n_proposals // 4)
    k_max = psis_khat_threshold(n_proposals)
    # standard Student-t variates u = z sqrt(nu / chi2), n_proposals for the first proposal and
    # as many for each round of adaptation; a proposal maps them to theta = centre + chol u
    u = rng.standard_normal((n_proposals, K))
    u *= np.sqrt(nu / rng.chisquare(nu, n_proposals))[:, None]
    offset = rng.random()  # of the systematic resampling, drawn whether or not it is used
    more = rng.standard_normal((IMPORTANCE_ADAPTATIONS, n_proposals, K))
    more *= np.sqrt(nu / rng.chisquare(nu, (IMPORTANCE_ADAPTATIONS, n_proposals)))[:, :, None]
    # each proposal's own extension, where its set is smaller than the PSIS threshold's cap
    grown = max(_PSIS_CAP_DRAWS - n_proposals, 0)
    extra = rng.standard_normal((1 + IMPORTANCE_ADAPTATIONS, grown, K))
    extra *= np.sqrt(nu / rng.chisquare(nu, (1 + IMPORTANCE_ADAPTATIONS, grown)))[:, :, None]

    def log_q(v):  # up to a constant of the proposal: -(nu + K) / 2 log(1 + |v|^2 / nu)
        return -0.5 * (nu + K) * np.log1p(np.sum(v * v, axis=1) / nu)

    def proposed(centre, chol, v):  # the proposals and their log weights
        theta = centre + v @ chol.T
        return theta, np.array([log_density(t) for t in theta], dtype=float) - log_q(v)

    def joined(theta, log_w, v):  # a set and more of the current proposal's, weighed
        rest, log_w_rest = proposed(centre, chol, v)
        log_w = np.concatenate([log_w, log_w_rest])
        return (np.vstack([theta, rest]), log_w, *_normalized(log_w),
                *_pareto_smoothed(log_w))

    laplace_chol = np.linalg.cholesky(cov)
    centre, chol = mode, laplace_chol
    n_weighed = 0
    for r, v in enumerate([u, *more]):
        theta, log_w = proposed(centre, chol, v[:pilot])
        n_weighed += pilot
        w, ess = _normalized(log_w)
        k = _pareto_smoothed(log_w)[1]
        found = ess * n_proposals / pilot  # projected to all the proposals
        moved = np.linalg.norm(np.linalg.solve(laplace_chol, centre - mode))
        logger.info("importance proposal %d (centre %.2f Laplace sd from the mode): ESS %.1f "
                    "of a pilot of %d (Pareto k %.2f), projected %.0f for %d samples", r,
                    moved, ess, pilot, k, found, n)
        if found >= n:  # the pilot suffices: the rest of this proposal's draws
            theta, log_w, w, ess, smoothed, k = joined(theta, log_w, v[pilot:])
            n_weighed += n_proposals - pilot
            found = ess
            logger.info("importance proposal %d: ESS %.1f of all %d proposals for %d samples, "
                        "Pareto k %.2f (at most %.2f)", r, ess, n_proposals, n, k, k_max)
            if ess >= n and k < k_max:
                break
            size = _psis_draws_for(k)
            if ess >= n and n_proposals < size <= _PSIS_CAP_DRAWS \
                    and (budget is None or n_weighed + size - n_proposals < budget):
                # only k fails, and below 0.7: the same proposal's set grown to the size whose
                # threshold k is under (PSIS's remedy for 1 - 1 / log10(S) <= k < 0.7)
                theta, log_w, w, ess, smoothed, k = joined(
                    theta, log_w, extra[r, :size - n_proposals])
                n_weighed += size - n_proposals
                found = ess
                logger.info("importance proposal %d: ESS %.1f of all %d proposals, grown for "
                            "its Pareto k, for %d samples, Pareto k %.2f (at most %.2f)", r,
                            ess, size, n, k, psis_khat_threshold(size))
                if ess >= n and k < psis_khat_threshold(size):
                    break
        if r == IMPORTANCE_ADAPTATIONS or ess == 0 \
                or (budget is not None and n_weighed + n_proposals >= budget):
            return None, found, n_weighed, k
        centre, shape = _adapted_proposal(theta, w, ess, cov)
        chol = np.linalg.cholesky(shape)
    # systematic resampling from the Pareto-smoothed weights: proposal i for the points u in
    # [c_{i-1}, c_i) of the running sums c (the last set to 1): a proposal of weight 0 has an
    # empty interval and is never picked; a point that rounding takes to 1 goes to the last
    # proposal of positive weight
    smoothed = np.exp(smoothed)  # of the set that passed, smoothed when it was tested
    cum = np.cumsum(smoothed)
    cum /= cum[-1]
    picks = np.searchsorted(cum, (offset + np.arange(n)) / n, side="right")
    return theta[np.minimum(picks, np.flatnonzero(smoothed)[-1])], ess, n_weighed, k


#: The number of importance draws from which PSIS's threshold on ``k``, ``1 - 1 /
#: log10(S)``, reaches its cap :data:`~irl.stats.PSIS_KHAT_MAX`: ``10^(1 / (1 - 0.7))``,
#: rounded up (2,155).
_PSIS_CAP_DRAWS = int(np.ceil(10.0 ** (1.0 / (1.0 - PSIS_KHAT_MAX))))


def _psis_draws_for(k: float) -> int:
    """The fewest importance draws whose PSIS threshold is above ``k``: ``S > 10^(1 / (1 -
    k))`` for ``k`` below the cap 0.7; more than :data:`_PSIS_CAP_DRAWS` (none suffices) from
    the cap on."""
    if not k < PSIS_KHAT_MAX:
        return _PSIS_CAP_DRAWS + 1
    return max(int(np.floor(10.0 ** (1.0 / (1.0 - k)))) + 1, 2)


def _pareto_smoothed(log_w: np.ndarray) -> tuple[np.ndarray | None, float]:
    """:func:`pareto_smoothed` of importance weights ``log_w[S]``: the smoothed log weights
    and their Pareto shape ``k``; ``(None, inf)`` where no weight is positive."""
    if not np.count_nonzero(np.isfinite(log_w)):
        return None, float("inf")
    return pareto_smoothed(log_w)


def _normalized(log_w: np.ndarray) -> tuple[np.ndarray, float]:
    """Importance weights summing to 1 from their logs (``-inf`` or NaN: weight 0), and their
    effective sample size ``1 / sum w^2`` (0 where every weight is 0)."""
    log_w = np.where(np.isnan(log_w), -np.inf, log_w)
    top = log_w.max()
    if not np.isfinite(top):
        return np.zeros(log_w.size), 0.0
    w = np.exp(log_w - top)
    w /= w.sum()
    return w, float(1.0 / np.sum(w * w))

