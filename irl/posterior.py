"""The posterior over reward weights, and how sure the learned policy is in each state.

Layouts: ``theta[n, k]`` posterior samples, ``policies[n, s]`` the greedy action of each
sample, ``confidence[s, a]``, ``Q[n, s, a]`` each sample's optimal Q-function.

MMAP-BIRL's log posterior ``log p(theta) + sum_demos log P(o | theta)`` is exact (every hidden
and noisy step marginalized by forward-backward) and so is its gradient. Two ways to draw from
it (:func:`sample_posterior`):

- ``"laplace"``: a Gaussian at the MAP whose precision is minus the Hessian of the exact log
  posterior, by central differences of the exact gradient (2K gradients). Fast, and exact when
  the posterior is Gaussian; blind to skew and to a second mode.
- ``"mcmc"``: Hamiltonian Monte Carlo with dynamic integration time and multinomial sampling
  (the No-U-Turn family) from the ``mici`` library, on the exact gradient, with the step size
  tuned by dual averaging during warm-up. The chains run in coordinates whitened by the Laplace
  covariance (``theta = MAP + L z``), so the sampler sees a near-standard normal. We chose a
  gradient sampler over an ensemble one because the exact gradient costs what the likelihood
  costs: on onion sorting (12 demonstrations, 6 weights), ``emcee``'s stretch move needed an
  autocorrelation time of about 43 steps and 29,000 likelihoods for split R-hat 1.09-1.16,
  where these chains reach R-hat below 1.01 with 21,000 gradients.

The greedy policy of a sample is the robot's policy had that sample been the truth;
:meth:`Posterior.action_confidence` is the share of samples whose greedy policy takes each
action in each state. :func:`map_policy_risk` scores the MAP policy against every sample (value
at risk), :func:`expected_regret` says where another demonstration is worth most.

Example::

    dom = irl.domains.onion_sorting(noise=0.45)
    demos, _ = dom.sample(n=2, length=10, occlusion=0.2, seed=0)
    est = irl.MMAPBIRL(dom.mdp, dom.observation_model, beta=dom.beta, prior=dom.prior)
    post = sample_posterior(est, demos, n_samples=1000, seed=0, method="laplace")
    post.action_confidence()          # (48, 5), rows sum to 1
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from irl._random import check_random_state
from irl._validation import check_int, check_real, describe
from irl.demonstrations import Demonstration
from irl.inference import scratch_held
from irl.learners.birl import MAPBIRL, MMAPBIRL
from irl.mdp import TabularMDP
from irl.solvers import OptimalQSolver, solve_policy_derivatives
from irl.stats import (
    PSIS_KHAT_MAX,
    effective_sample_size,
    pareto_smoothed,
    psis_khat_threshold,
    split_rhat,
)

__all__ = [
    "IMPORTANCE_ADAPTATIONS",
    "IMPORTANCE_PROPOSALS",
    "LAPLACE_SHARE",
    "METHODS",
    "Diagnostics",
    "PolicyRisk",
    "Posterior",
    "SwapComponent",
    "expected_regret",
    "load_posterior",
    "map_policy_risk",
    "sample_posterior",
    "swap_readings",
]

logger = logging.getLogger(__name__)

#: The ways :func:`sample_posterior` draws.
METHODS = ("laplace", "mcmc")

POSTERIOR_FORMAT = "onionsort.posterior/1"


@dataclass(frozen=True)
class Diagnostics:
    """How far the samples can be trusted.

    Attributes
    ----------
    r_hat : ndarray of shape (K,)
        Rank-normalized split R-hat per weight (:func:`irl.stats.split_rhat`); NaN for the
        Laplace draws, which are independent by construction.
    ess : ndarray of shape (K,)
        Bulk effective sample size per weight; the number of draws for Laplace.
    acceptance : float
        Mean acceptance statistic of the main (post warm-up) transitions; 1 for Laplace.
    n_chains, n_warmup, n_draws : int
        Chains, warm-up iterations and main draws per chain (1, 0, n for Laplace).
    n_divergent : int
        Main transitions whose energy error diverged (0 for Laplace).
    n_gradients : int
        Gradients of the exact log posterior evaluated, warm-up included (with a session swap,
        a resampled reading's proposals count here too, though each costs a value alone).
    hessian_clipped : int
        Eigenvalues of minus the Hessian at the MAP raised to the prior's precision (the
        Hessian by differences can miss curvature where the MAP lies on the border between two
        greedy policies).
    """

    r_hat: np.ndarray
    ess: np.ndarray
    acceptance: float
    n_chains: int
    n_warmup: int
    n_draws: int
    n_divergent: int
    n_gradients: int
    hessian_clipped: int

    def max_r_hat(self) -> float:
        """The largest R-hat over the weights (NaN for Laplace)."""
        return float(np.max(self.r_hat)) if np.all(np.isfinite(self.r_hat)) else float("nan")

    def to_dict(self) -> dict:
        return {
            "r_hat": [None if not np.isfinite(v) else round(float(v), 5) for v in self.r_hat],
            "ess": [round(float(v), 1) for v in self.ess],
            "acceptance": round(float(self.acceptance), 4),
            "n_chains": self.n_chains, "n_warmup": self.n_warmup, "n_draws": self.n_draws,
            "n_divergent": self.n_divergent, "n_gradients": self.n_gradients,
            "hessian_clipped": self.hessian_clipped,
        }


@dataclass(frozen=True)
class SwapComponent:
    """One reading of the demonstrations in the posterior of a learner with a
    ``session_swap``: which demonstrations it reads swapped, and its share.

    Attributes
    ----------
    swapped : tuple of int
        The demonstrations (their indices) read through the swap.
    weight : float
        Its posterior probability among the readings weighed (they sum to 1).
    log_weight : float
        Its prior probability times its evidence, in logs: ``|z| log rate + (N - |z|)
        log(1 - rate)`` plus the Laplace approximation of ``log p(o_z)`` at its mode.
    n_samples : int
        The posterior's samples drawn from it.
    """

    swapped: tuple[int, ...]
    weight: float
    log_weight: float
    n_samples: int


@dataclass(frozen=True)
class Posterior:
    """Samples of the reward weights given the demonstrations, and their greedy policies.

    Attributes
    ----------
    theta : ndarray of shape (n, K)
    policies : ndarray of shape (n, S)
        The greedy optimal policy of each sample.
    map_theta : ndarray of shape (K,)
        The MAP the samples were drawn around (the estimator's ``theta_``).
    map_policy : ndarray of shape (S,)
    covariance : ndarray of shape (K, K)
        The Laplace covariance at the MAP (the proposal's shape for ``"mcmc"``; with a
        ``session_swap``, of the mixture posterior, while each reading is drawn with its own).
    n_actions : int
    method : str
    diagnostics : Diagnostics
    components : tuple of SwapComponent
        With a learner's ``session_swap``: the readings of the demonstrations weighed, and how
        many samples each gave (empty otherwise).
    """

    theta: np.ndarray
    policies: np.ndarray
    map_theta: np.ndarray
    map_policy: np.ndarray
    covariance: np.ndarray
    n_actions: int
    method: str
    diagnostics: Diagnostics
    components: tuple[SwapComponent, ...] = ()
    _confidence: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        n, S = self.policies.shape
        if self.theta.shape[0] != n:
            raise ValueError(f"theta has {self.theta.shape[0]} samples but policies has {n}")
        counts = np.zeros((S, self.n_actions))
        np.add.at(counts, (np.broadcast_to(np.arange(S), (n, S)), self.policies), 1.0)
        object.__setattr__(self, "_confidence", counts / n)

    @property
    def n_samples(self) -> int:
        return int(self.theta.shape[0])

    def action_confidence(self) -> np.ndarray:
        """``confidence[s, a]``: the share of samples whose greedy policy takes ``a`` in ``s``.
        Each row sums to 1."""
        return self._confidence.copy()

    def map_confidence(self) -> np.ndarray:
        """``(S,)``: the confidence in the MAP policy's action in each state."""
        return self._confidence[np.arange(self.map_policy.size), self.map_policy]

    def credible_actions(self, level: float = 0.9) -> list[tuple[int, ...]]:
        """Per state, the fewest actions whose confidence sums to at least ``level``, the most
        confident first."""
        level = check_real(level, "level", low=0.0, high=1.0, low_open=True)
        sets = []
        for row in self._confidence:
            order = np.argsort(-row, kind="stable")
            k = int(np.searchsorted(np.cumsum(row[order]), level - 1e-12)) + 1
            sets.append(tuple(int(a) for a in order[:min(k, row.size)]))
        return sets

    def save(self, path: Path) -> Path:
        """Write the samples to ``path`` (``.npz``), through a temporary name."""
        path = Path(path)
        tmp = path.with_name(path.name + ".partial")
        with open(tmp, "wb") as f:
            np.savez_compressed(
                f, format=POSTERIOR_FORMAT, theta=self.theta, policies=self.policies,
                map_theta=self.map_theta, map_policy=self.map_policy,
                covariance=self.covariance, n_actions=self.n_actions, method=self.method,
                **{f"diag_{k}": np.asarray(getattr(self.diagnostics, k))
                   for k in Diagnostics.__dataclass_fields__},
                **_components_arrays(self.components))
        tmp.replace(path)
        return path


def load_posterior(path: Path) -> Posterior:
    """Read a :meth:`Posterior.save` file; a one-line ``ValueError`` if it is not one."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no such posterior file: {path}")
    try:
        with np.load(path, allow_pickle=False) as z:
            if str(z["format"]) != POSTERIOR_FORMAT:
                raise ValueError(f"format {str(z['format'])!r}, not {POSTERIOR_FORMAT!r}")
            diag = {k: z[f"diag_{k}"] for k in Diagnostics.__dataclass_fields__}
            return Posterior(
                theta=z["theta"], policies=z["policies"].astype(np.int64),
                map_theta=z["map_theta"], map_policy=z["map_policy"].astype(np.int64),
                covariance=z["covariance"], n_actions=int(z["n_actions"]),
                method=str(z["method"]),
                diagnostics=Diagnostics(
                    r_hat=diag["r_hat"], ess=diag["ess"], acceptance=float(diag["acceptance"]),
                    **{k: int(diag[k]) for k in ("n_chains", "n_warmup", "n_draws",
                                                 "n_divergent", "n_gradients",
                                                 "hessian_clipped")}),
                components=_read_components(z))
    except (OSError, KeyError, ValueError) as exc:
        raise ValueError(f"{path} is not a posterior file ({exc})") from None


def _components_arrays(components: tuple[SwapComponent, ...]) -> dict[str, np.ndarray]:
    """The swap readings as arrays (``swapped`` as a padded index matrix; -1 pads)."""
    if not components:
        return {}
    width = max(1, max(len(c.swapped) for c in components))
    swapped = np.full((len(components), width), -1, dtype=np.int64)
    for i, c in enumerate(components):
        swapped[i, :len(c.swapped)] = c.swapped
    return {"comp_swapped": swapped,
            "comp_weight": np.array([c.weight for c in components]),
            "comp_log_weight": np.array([c.log_weight for c in components]),
            "comp_n_samples": np.array([c.n_samples for c in components], dtype=np.int64)}


def _read_components(z) -> tuple[SwapComponent, ...]:
    if "comp_swapped" not in z:
        return ()
    return tuple(SwapComponent(swapped=tuple(int(i) for i in row if i >= 0), weight=float(w),
                               log_weight=float(lw), n_samples=int(n))
                 for row, w, lw, n in zip(z["comp_swapped"], z["comp_weight"],
                                          z["comp_log_weight"], z["comp_n_samples"],
                                          strict=True))


# -- sampling ---------------------------------------------------------------------------------


def _check_estimator(estimator):
    if not isinstance(estimator, MMAPBIRL | MAPBIRL):
        raise TypeError("estimator must be an irl.MMAPBIRL or irl.MAPBIRL (a Bayesian learner "
                        f"with an exact log posterior); got {describe(estimator)}")
    return estimator


def _fitted_map(estimator, demos) -> tuple[np.ndarray, object]:
    """The MAP and the ``theta -> (log posterior, gradient)`` of the estimator. A fitted
    estimator's ``theta_`` is the MAP (the policy the robot runs is its greedy one, and the
    confidence is about that policy); an unfitted one is fitted on a copy."""
    if hasattr(estimator, "theta_"):
        return np.asarray(estimator.theta_, float), estimator.log_posterior_function(demos)
    fitted = type(estimator)(**estimator.get_params()).fit(demos)
    return np.asarray(fitted.theta_, float), fitted.log_posterior_function(demos)


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


def _greedy_policies(mdp: TabularMDP, theta: np.ndarray) -> np.ndarray:
    solver = OptimalQSolver(mdp)
    return np.stack([solver.solve(t).policy for t in theta]).astype(np.int64)


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


def sample_posterior(
    estimator,
    demonstrations: Sequence[Demonstration],
    n_samples: int = 1000,
    seed: int | np.random.Generator | None = 0,
    method: str = "mcmc",
    *,
    n_chains: int = 4,
    n_warmup: int = 200,
    n_draws: int | None = None,
    max_draws: int | None = None,
    step: float = 1e-4,
) -> Posterior:
    """Draw reward weights from the estimator's exact posterior given the demonstrations.

    Parameters
    ----------
    estimator : MMAPBIRL or MAPBIRL
        Its model (MDP, observation model of any kind, beta, prior, backend, session swap)
        defines the posterior. If it is fitted (on these demonstrations), its ``theta_`` is
        the MAP the samples are drawn around (with a session swap, the MAP whose policy the
        confidence is about, each reading being drawn round its own mode) and its greedy
        policy the one the confidence is about; otherwise a copy is fitted. It is not
        changed.
    demonstrations : sequence of Demonstration
    n_samples : int, default 1000
        Samples returned (the main draws of all chains, thinned evenly to this many; with a
        session swap, each reading's share of them, thinned from its own chains).
    seed : int, Generator or None, default 0
        The same seed gives the same samples.
    method : {"mcmc", "laplace"}
        See the module's docstring.
    n_chains : int, default 4
        Chains of ``"mcmc"``; their agreement is the R-hat.
    n_warmup : int, default 200
        Warm-up (step-size adaptation) iterations per chain, discarded.
    n_draws : int, optional
        Main draws per chain; by default ``max(400, ceil(n_samples / n_chains))``.
    max_draws : int, optional
        While the chains disagree (a weight's split R-hat above 1.01), they are extended by
        ``n_draws`` at a time up to this many draws each; by default ``3 * n_draws``. Equal
        to ``n_draws``, never.
    step : float, default 1e-4
        Relative step of the differences that give the Hessian at the MAP.

    With an :class:`~irl.MMAPBIRL` whose ``session_swap`` is set, the posterior has one mode
    per reading of the demonstrations (which of them were read swapped), and a chain started at
    one does not cross to another (the reward read backwards is far from the reward read
    right). So the readings of :func:`swap_readings` are weighed one by one: each is fitted
    without the swap on the demonstrations so read, weighted by its prior probability times
    its Laplace evidence, and drawn from as above in proportion to its weight
    (:attr:`Posterior.components`), its chains' ``n_draws`` scaled by its share of the
    samples (and extended up to ``max_draws`` while they disagree, a reading other than the
    heaviest while its gradients are fewer than the heaviest's); the lightest readings,
    together at most :data:`LAPLACE_SHARE` of the weight, are drawn from their Laplace
    approximation, and the others but the heaviest by importance resampling from it (adapted
    where it misses) where that is cheaper than chains and its effective sample size suffices
    (:data:`IMPORTANCE_PROPOSALS`, :data:`IMPORTANCE_ADAPTATIONS`). Readings outside that set
    are not weighed.

    Returns
    -------
    Posterior
    """
    estimator = _check_estimator(estimator)
    n_samples = check_int(n_samples, "n_samples", low=1)
    if not isinstance(method, str) or method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}; got {method!r}")
    n_chains = check_int(n_chains, "n_chains", low=2)
    n_warmup = check_int(n_warmup, "n_warmup", low=1)
    if n_draws is None:
        n_draws = max(400, -(-n_samples // n_chains))
    n_draws = check_int(n_draws, "n_draws", low=4)
    max_draws = check_int(3 * n_draws if max_draws is None else max_draws, "max_draws",
                          low=n_draws)
    step = check_real(step, "step", low=0.0, high=0.1, low_open=True)
    rng = check_random_state(seed)
    mdp = estimator.mdp
    demonstrations = list(demonstrations)
    draw = {"method": method, "rng": rng, "n_chains": n_chains, "n_warmup": n_warmup,
            "n_draws": n_draws, "max_draws": max_draws, "step": step}

    with scratch_held():
        map_theta, value_and_grad = _fitted_map(estimator, demonstrations)
        _, std = estimator._check_model().prior._broadcast(map_theta.size)
        if getattr(estimator, "session_swap", None) is None:
            theta, diagnostics, cov = _draw(value_and_grad, map_theta, 1.0 / std**2, n_samples,
                                            **draw)
            components: tuple[SwapComponent, ...] = ()
        else:
            theta, diagnostics, components = _draw_swap_readings(
                estimator, demonstrations, map_theta, 1.0 / std**2, n_samples, draw)
            cov = _laplace_covariance(value_and_grad, map_theta, 1.0 / std**2, step)[0]
    if np.isfinite(diagnostics.max_r_hat()) and diagnostics.max_r_hat() > 1.01:
        logger.warning("the chains still disagree after %d draws each (max R-hat %.3f > "
                       "1.01): raise max_draws or n_warmup", diagnostics.n_draws,
                       diagnostics.max_r_hat())
    map_policy, *policies = _greedy_policies(mdp, np.vstack([map_theta, theta]))
    return Posterior(theta=theta, policies=np.stack(policies), map_theta=map_theta,
                     map_policy=map_policy, covariance=cov, n_actions=mdp.n_actions,
                     method=method, diagnostics=diagnostics, components=components)


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


def swap_readings(p_swapped: np.ndarray) -> list[tuple[int, ...]]:
    """The readings of N demonstrations (which of them were read swapped) whose posterior
    weight :func:`sample_posterior` measures: the reading the MAP implies (each demonstration
    swapped where ``p_swapped`` is above 0.5), its complement (the same data explained by the
    reward read backwards), and every reading one demonstration away from either."""
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


# -- what the posterior says about the MAP policy ----------------------------------------------


@dataclass(frozen=True)
class PolicyRisk:
    """How the MAP policy would fare if each sample were the true reward.

    Attributes
    ----------
    ile : ndarray of shape (n,)
        ``sum_s |V*(s) - V^MAP(s)|`` under each sample's reward (the inverse learning error the
        MAP policy would have).
    normalized_ile : ndarray of shape (n,)
        ``100 * ile / ||V*||_1`` (percent).
    optimal : ndarray of shape (n,), bool
        Whether the MAP policy is optimal for the sample (values equal to rounding).
    """

    ile: np.ndarray
    normalized_ile: np.ndarray
    optimal: np.ndarray

    @property
    def expected_ile(self) -> float:
        return float(self.ile.mean())

    @property
    def expected_normalized_ile(self) -> float:
        return float(self.normalized_ile.mean())

    @property
    def p_optimal(self) -> float:
        """The posterior probability that the MAP policy is optimal."""
        return float(self.optimal.mean())

    def to_dict(self) -> dict:
        return {"expected_ile": round(self.expected_ile, 6),
                "expected_normalized_ile": round(self.expected_normalized_ile, 4),
                "p_map_optimal": round(self.p_optimal, 4),
                "ile_quantiles": {str(q): round(float(np.quantile(self.ile, q)), 6)
                                  for q in (0.5, 0.9, 0.95)}}


def _sample_q_values(posterior: Posterior, mdp: TabularMDP) -> np.ndarray:
    """``Q[n, s, a]``: each sample's optimal Q-function. ``Q^pi = dQ^pi theta`` is linear in
    theta for a fixed policy, so one linear solve per distinct greedy policy serves all the
    samples that share it."""
    unique, which = np.unique(posterior.policies, axis=0, return_inverse=True)
    Q = np.empty((posterior.n_samples, mdp.n_states, mdp.n_actions))
    for u, policy in enumerate(unique):
        rows = np.flatnonzero(which.reshape(-1) == u)
        Q[rows] = np.einsum("sak,nk->nsa", solve_policy_derivatives(mdp, policy),
                            posterior.theta[rows])
    return Q


def map_policy_risk(posterior: Posterior, mdp: TabularMDP) -> PolicyRisk:
    """Score the MAP policy under every sample's reward (its value at risk)."""
    _check_posterior(posterior, mdp)
    Q = _sample_q_values(posterior, mdp)
    states = np.arange(mdp.n_states)
    v_best = Q.max(axis=2)
    dV = solve_policy_derivatives(mdp, posterior.map_policy)[states, posterior.map_policy]
    v_map = posterior.theta @ dV.T  # (n, S)
    gap = np.abs(v_best - v_map).sum(axis=1)
    scale = np.abs(v_best).sum(axis=1)
    normalized = np.divide(100.0 * gap, scale, out=np.zeros_like(gap), where=scale > 0)
    return PolicyRisk(ile=gap, normalized_ile=normalized,
                      optimal=gap <= 1e-9 * np.maximum(1.0, scale))


def expected_regret(posterior: Posterior, mdp: TabularMDP) -> np.ndarray:
    """``(S,)``: ``E[max_a Q(s, a) - Q(s, pi_MAP(s))]`` over the posterior.

    What the MAP policy's action in ``s`` is expected to give up against the best action, in
    reward units: the value of perfect information about the best action in ``s``, and so an
    upper bound on what a demonstration in ``s`` can gain the robot there. Zero where every
    sample agrees with the MAP action.
    """
    _check_posterior(posterior, mdp)
    Q = _sample_q_values(posterior, mdp)
    taken = Q[:, np.arange(mdp.n_states), posterior.map_policy]
    return (Q.max(axis=2) - taken).mean(axis=0)


def _check_posterior(posterior, mdp) -> None:
    if not isinstance(posterior, Posterior):
        raise TypeError(f"posterior must be an irl.posterior.Posterior; got "
                        f"{describe(posterior)}")
    if not isinstance(mdp, TabularMDP):
        raise TypeError(f"mdp must be an irl.TabularMDP; got {describe(mdp)}")
    if posterior.policies.shape[1] != mdp.n_states or posterior.theta.shape[1] != mdp.n_features:
        raise ValueError(
            f"the posterior is over {posterior.theta.shape[1]} weights of "
            f"{posterior.policies.shape[1]} states; the mdp has {mdp.n_features} and "
            f"{mdp.n_states}")
