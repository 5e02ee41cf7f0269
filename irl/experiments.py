"""Sweeps of the paper's experiments: ILE, exact-policy recovery and run time, with intervals.

A sweep is a list of :class:`Trial` (method, occlusion, noise, demonstrations, length, learner
setting, batch). Each trial draws its batch of demonstrations from seeds derived from (sweep
seed, occlusion, noise, length, batch, demonstration index), so every method and every learner
setting sees the same data, a batch of ``n`` demonstrations is the first ``n`` of a larger one
(a paired design along the number of demonstrations), and any trial can be re-run alone. Trials
are independent: :func:`run_trials` runs them on a process pool or on any
:class:`concurrent.futures.Executor` (the ``onionsort experiment`` stage passes a Ray-backed one),
and a trial's result does not depend on where or in which order it ran.

The data always come from the domain's true expert (its ``beta``). The learners can be fitted
with another beta: a :data:`learner setting <SweepConfig.learners>` is a number (the beta
itself), a factor of the domain's beta written ``"x0.5"``, or ``"paper"`` (the paper's beta 0.03
with the domain's prior). Learners without a ``beta`` (HiddenDataEM, MaxEnt IRL) are built the
same way and simply have nothing to change: their fit is made once per batch and stands for
every setting (each row names its setting and beta, as if fitted for it).

The forward-backward kernels (``SweepConfig.backend``: numpy or numba) are how a trial is
computed, not what: they go to the learners that have a ``backend`` parameter
(:func:`irl.learners.make_estimator`), give the same results to rounding, and are recorded in
each result, but are no part of a trial's identity or seeds.

:func:`summarize` reports, per (method, occlusion, noise, trajectories, length, learner setting),
means over batches with percentile-bootstrap confidence intervals (:func:`irl.stats.bootstrap_ci`)
seeded from the sweep seed.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
import warnings
import zlib
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass

import numpy as np

from irl.demonstrations import observe, sample_trajectory
from irl.domains import Domain, forestworld, onion_sorting
from irl.domains.onion_sorting import reachable_states as sorting_reachable_states
from irl.exceptions import ConvergenceWarning
from irl.inference import check_backend
from irl.learners.registry import LEARNERS, make_estimator
from irl.metrics import inverse_learning_error, normalized_inverse_learning_error, policy_mismatch
from irl.stats import bootstrap_ci

__all__ = [
    "DOMAINS",
    "METHODS",
    "PAPER_BETA",
    "REWARD_METHODS",
    "SweepConfig",
    "Trial",
    "TrialResult",
    "learner_domain",
    "make_estimator",
    "parse_learner_setting",
    "result_rows",
    "run_sweep",
    "run_trial",
    "run_trials",
    "sample_batch",
    "summarize",
]

logger = logging.getLogger(__name__)

DOMAINS: dict[str, Callable[..., Domain]] = {
    "forestworld": forestworld,
    "sorting": onion_sorting,
}
#: States on which a learned greedy policy must equal the expert's for ``exact_policy``: those
#: reachable from the initial states where the domain defines them, all states otherwise.
REACHABLE_STATES: dict[str, Callable[[], Sequence[int]]] = {
    "sorting": sorting_reachable_states,
}
#: The registered learners, in registration order (the paper's four, then behaviour cloning's
#: ``bc`` and ``bc-em``); a sweep may also name any learner registered
#: since (:func:`irl.learners.register_learner`; with ``workers > 1`` it must be registered on
#: import of a module the workers import too).
METHODS = tuple(LEARNERS)
#: The paper's four reward learners: what a sweep runs unless told (behaviour cloning is asked
#: for by name, as ``onionsort experiment --methods`` asks for it).
REWARD_METHODS = ("mmap-birl", "map-birl", "hidden-data-em", "maxent")
#: The Boltzmann rationality the paper uses for its learners (Section 5).
PAPER_BETA = 0.03
#: Bootstrap settings of :func:`summarize`.
N_RESAMPLES = 2000
CONFIDENCE = 0.95


def parse_learner_setting(setting) -> str:
    """The canonical label of one learner setting: ``"paper"``, ``"x<factor>"`` or a beta.

    ``"x0.50"`` becomes ``"x0.5"``, ``1.5`` and ``"1.50"`` become ``"1.5"``. A ``ValueError``
    names the value unless it is ``"paper"``, a positive finite factor or a positive finite beta.

    Parameters
    ----------
    setting : str or float
        ``"paper"``, ``"x<factor>"`` of the domain's beta, or a beta.

    Returns
    -------
    str
        The canonical label.
    """
    text = str(setting).strip().lower()
    if text == "paper":
        return text
    factor = text.startswith("x")
    try:
        value = float(text[1:] if factor else text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise ValueError(
            "learner_beta must be positive numbers (betas), factors of the domain's beta such "
            f"as x0.5, or 'paper'; got {setting!r}"
        )
    return f"x{value:g}" if factor else f"{value:g}"


def learner_domain(domain: Domain, setting: str) -> Domain:
    """``domain`` as the learners are told it: the beta (and prior) of ``setting``.

    ``"x<f>"`` multiplies the domain's beta by ``f``; a number replaces it; ``"paper"`` is the
    paper's beta 0.03 with the domain's prior (on Forestworld the paper's N(-1, 0.5); the paper
    names no prior for sorting). The true reward and the observation model are unchanged.

    Parameters
    ----------
    domain : Domain
    setting : str
        A learner setting (:func:`parse_learner_setting`).

    Returns
    -------
    Domain
        A copy of ``domain`` with the learners' beta.
    """
    label = parse_learner_setting(setting)
    if label == "paper":
        beta = PAPER_BETA
    elif label.startswith("x"):
        beta = domain.beta * float(label[1:])
    else:
        beta = float(label)
    return dataclasses.replace(domain, beta=beta)


@dataclass(frozen=True)
class SweepConfig:
    """What to sweep.

    Attributes
    ----------
    domain : str
        A key of :data:`DOMAINS`.
    points : tuple of (occlusion, noise)
    methods : tuple of str
        Keys of :data:`irl.learners.LEARNERS`; by default :data:`REWARD_METHODS`.
    batches : int
        Batches (independent data sets) per point.
    trajectories : int or tuple of int
        Demonstrations per batch; several values sweep the amount of data.
    length : int or tuple of int
        Steps per demonstration; several values sweep it.
    learners : tuple of str
        Learner settings (see :func:`parse_learner_setting`); ``("x1",)``: the true beta.
    seed : int
        Seeds the data of every batch and the bootstrap of :func:`summarize`.
    backend : {"numpy", "numba"}
        Forward-backward kernels of the learners that have a ``backend`` parameter
        (:data:`irl.inference.BACKENDS`); equal to rounding, so not part of the data or seeds.
    """

    domain: str
    points: tuple[tuple[float, float], ...]
    methods: tuple[str, ...] = REWARD_METHODS
    batches: int = 10
    trajectories: int | tuple[int, ...] = 10
    length: int | tuple[int, ...] = 20
    learners: tuple[str, ...] = ("x1",)
    seed: int = 0
    backend: str = "numpy"

    def __post_init__(self) -> None:
        check_backend(self.backend)
        if self.domain not in DOMAINS:
            raise ValueError(f"domain must be one of {sorted(DOMAINS)}; got {self.domain!r}")
        unknown = [m for m in self.methods if m not in LEARNERS]
        if unknown:
            raise ValueError(f"methods must be among {tuple(LEARNERS)}; got {unknown}")
        if not self.methods:
            raise ValueError("methods must name at least one learner; got none")
        for name in ("trajectories", "length"):
            values = getattr(self, name)
            values = (values,) if isinstance(values, int | np.integer) else tuple(values)
            if not values:
                raise ValueError(f"{name} must have at least one value; got none")
            for v in values:
                if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < 1:
                    raise ValueError(f"{name} must be integers >= 1; got {v!r}")
            object.__setattr__(self, name, tuple(int(v) for v in dict.fromkeys(values)))
        if self.batches < 1:
            raise ValueError(f"batches must be >= 1; got {self.batches}")
        if not self.learners:
            raise ValueError("learners must have at least one setting; got none")
        object.__setattr__(self, "learners", tuple(dict.fromkeys(
            parse_learner_setting(s) for s in self.learners)))
        for occ, noise in self.points:
            if not 0.0 <= occ < 1.0:
                raise ValueError(f"occlusion must be in [0, 1); got {occ}")
            if not 0.0 <= noise < 1.0:
                raise ValueError(f"noise must be in [0, 1); got {noise}")

    def trials(self) -> list[Trial]:
        return [
            Trial(self.domain, m, occ, noise, b, n, length, self.seed, learner, self.backend)
            for occ, noise in self.points
            for length in self.length
            for n in self.trajectories
            for b in range(self.batches)
            for learner in self.learners
            for m in self.methods
        ]


@dataclass(frozen=True)
class Trial:
    """One fit of one method on one batch of one point of a sweep.

    Attributes
    ----------
    domain : str
        ``"forestworld"`` or ``"sorting"``.
    method : str
        A key of :data:`irl.learners.LEARNERS`.
    occlusion, noise : float
        The point.
    batch : int
        The batch's index at the point.
    trajectories, length : int
        Demonstrations in the batch, and steps in each.
    seed : int
        The sweep's seed (see :meth:`data_seed`).
    learner : str
        The learner setting (:func:`parse_learner_setting`).
    backend : str
        Forward-backward kernels (numpy or numba); not part of the data seeds.
    """

    domain: str
    method: str
    occlusion: float
    noise: float
    batch: int
    trajectories: int
    length: int
    seed: int
    learner: str = "x1"
    backend: str = "numpy"

    def data_seed(self, index: int) -> np.random.SeedSequence:
        """Seed of the batch's ``index``-th demonstration: shared by all methods, all learner
        settings and all batch sizes of one (occlusion, noise, length, batch)."""
        key = [self.seed, round(self.occlusion * 1000), round(self.noise * 1000), self.length,
               self.batch, index]
        return np.random.SeedSequence(key)


@dataclass(frozen=True)
class TrialResult:
    """How one trial's fit did.

    Attributes
    ----------
    method : str
    occlusion, noise : float
    batch : int
        As the trial's.
    ile, normalized_ile : float
        :func:`irl.inverse_learning_error` and the same in percent of the expert's value.
    seconds : float
        The fit's wall-clock time (the only field that differs between runs).
    n_iter : int
        The learner's ``n_iter_``.
    converged : bool
        Whether the fit gave no :class:`~irl.ConvergenceWarning`.
    trajectories, length : int
    learner : str
        As the trial's.
    learner_beta : float
        The beta of the learner setting (a learner without a beta ignores it).
    exact_policy : int
        1 where the learned policy is optimal in every (reachable) state, else 0.
    backend : str
        The trial's kernels, used by the learners that run forward-backward.
    """

    method: str
    occlusion: float
    noise: float
    batch: int
    ile: float
    normalized_ile: float
    seconds: float
    n_iter: int
    converged: bool
    trajectories: int = 0
    length: int = 0
    learner: str = "x1"
    learner_beta: float = math.nan
    exact_policy: int = 0
    backend: str = "numpy"


def sample_batch(domain: Domain, trial: Trial) -> list:
    """The trial's demonstrations, each from its own seed (see :meth:`Trial.data_seed`).

    Parameters
    ----------
    domain : Domain
        The trial's domain at its noise.
    trial : Trial

    Returns
    -------
    list of Demonstration
        ``trial.trajectories`` of them.
    """
    policy = domain.expert_policy()
    demos = []
    for i in range(trial.trajectories):
        rng = np.random.default_rng(trial.data_seed(i))
        tr = sample_trajectory(domain.mdp, policy, trial.length, rng)
        demos.append(observe(tr, domain.observation_model, trial.occlusion, rng))
    return demos


def run_trial(trial: Trial) -> TrialResult:
    """Sample the trial's batch, fit its method with its learner setting, and score it.

    Parameters
    ----------
    trial : Trial

    Returns
    -------
    TrialResult
    """
    domain = DOMAINS[trial.domain](noise=trial.noise)
    demos = sample_batch(domain, trial)
    told = learner_domain(domain, trial.learner)
    est = make_estimator(trial.method, told, seed=trial.batch, backend=trial.backend)
    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ConvergenceWarning)
        est.fit(demos)
    seconds = time.perf_counter() - start
    converged = not any(issubclass(w.category, ConvergenceWarning) for w in caught)
    states = REACHABLE_STATES[trial.domain]() if trial.domain in REACHABLE_STATES else None
    mdp, theta = domain.mdp, domain.true_theta
    # a learner with a reward is scored by its reward's greedy policy, one without (behaviour
    # cloning, theta_ None) by its own policy_
    learned = ({"policy": est.policy_} if getattr(est, "theta_", None) is None
               else {"learned_theta": est.theta_})
    return TrialResult(
        method=trial.method,
        occlusion=trial.occlusion,
        noise=trial.noise,
        batch=trial.batch,
        ile=inverse_learning_error(mdp, theta, **learned),
        normalized_ile=normalized_inverse_learning_error(mdp, theta, **learned),
        seconds=seconds,
        n_iter=int(est.n_iter_),
        converged=converged,
        trajectories=trial.trajectories,
        length=trial.length,
        learner=trial.learner,
        learner_beta=float(told.beta),
        exact_policy=int(policy_mismatch(mdp, theta, states=states, **learned) == 0),
        backend=trial.backend,
    )


def run_trials(
    trials: Sequence[Trial], *, workers: int = 1, executor: Executor | None = None
) -> Iterator[tuple[int, TrialResult]]:
    """Run ``trials``, yielding ``(position in trials, result)`` as each finishes.

    Parameters
    ----------
    trials : sequence of Trial
    workers : int
        Without ``executor``: ``1`` runs the trials here, in order; more runs them on a process
        pool of that many workers, yielding in the order they finish.
    executor : concurrent.futures.Executor, optional
        Runs the trials instead (e.g. on a cluster); ``workers`` is then not used. It is not
        shut down here. Trials are submitted as ``executor.submit(run_trial, trial)``, so it
        must be able to ship both to its workers.

    A trial's result depends only on the trial (its seeds come from its fields), never on the
    executor or on the order of completion; only ``seconds`` differs from run to run. Trials
    that differ only in a learner setting their method does not use share one fit (see
    :func:`_shared_fits`), yielded for each of them. When the caller stops iterating early,
    trials not yet started are cancelled.

    Yields
    ------
    index : int
        The trial's position in ``trials``.
    result : TrialResult
    """
    trials = list(trials)
    shared = _shared_fits(trials)

    def each(i: int, result: TrialResult) -> Iterator[tuple[int, TrialResult]]:
        for j in shared[i]:
            yield j, result if j == i else _as_setting(result, trials[j])

    if executor is None and workers <= 1:
        for i in shared:
            yield from each(i, run_trial(trials[i]))
        return
    pool = executor if executor is not None else ProcessPoolExecutor(max_workers=workers)
    futures = {}
    try:
        futures = {pool.submit(run_trial, trials[i]): i for i in shared}
        for future in as_completed(futures):
            yield from each(futures[future], future.result())
    finally:
        for future in futures:
            future.cancel()
        if executor is None:
            pool.shutdown(wait=True, cancel_futures=True)


def _shared_fits(trials: Sequence[Trial]) -> dict[int, list[int]]:
    """The trials to run, each with the trials its fit stands for: ``{i: [i, j, ...]}`` in
    trial order. Trials that differ only in the learner setting share one fit when their
    method's estimator does not depend on the learner's beta (:func:`_ignores_beta`:
    HiddenDataEM and MaxEnt IRL have none), since the data and the fit are then the same."""
    groups: dict[Trial, list[int]] = {}
    free: dict[tuple, bool] = {}  # per call: a learner may be registered again, differently
    several = len({t.learner for t in trials}) > 1
    for i, trial in enumerate(trials):
        kind = (trial.domain, trial.noise, trial.method)
        if kind not in free:
            free[kind] = several and _ignores_beta(*kind)
        key = dataclasses.replace(trial, learner="") if free[kind] else trial
        groups.setdefault(key, []).append(i)
    return {members[0]: members for members in groups.values()}


def _ignores_beta(domain: str, noise: float, method: str) -> bool:
    """Whether ``method``'s estimator is built the same for two learner betas (the only thing
    a learner setting changes, :func:`learner_domain`): the same parameters (objects by
    identity and values by equality). False for an estimator without ``get_params``."""
    told = DOMAINS[domain](noise=noise)
    built = [make_estimator(method, dataclasses.replace(told, beta=beta), seed=0)
             for beta in (told.beta, 2.0 * told.beta)]
    if not all(callable(getattr(e, "get_params", None)) for e in built):
        return False  # nothing to compare: fitted at every setting
    a, b = (e.get_params() for e in built)
    return a.keys() == b.keys() and all(_same_param(a[k], b[k]) for k in a)


def _same_param(x, y) -> bool:
    if x is y:
        return True
    if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
        return isinstance(x, np.ndarray) and isinstance(y, np.ndarray) \
            and x.shape == y.shape and bool(np.array_equal(x, y))
    try:
        return bool(x == y)
    except (TypeError, ValueError):  # an object whose == is not a truth value
        return False


def _as_setting(result: TrialResult, trial: Trial) -> TrialResult:
    """``result``, a shared fit's, as ``trial``'s: its learner setting and that beta."""
    told = learner_domain(DOMAINS[trial.domain](noise=trial.noise), trial.learner)
    return dataclasses.replace(result, learner=trial.learner, learner_beta=float(told.beta))


def run_sweep(
    config: SweepConfig, *, workers: int = 1, executor: Executor | None = None
) -> Iterator[TrialResult]:
    """Run every trial of the sweep, yielding results in trial order (:meth:`SweepConfig.trials`).

    ``workers`` and ``executor`` are those of :func:`run_trials`. With ``workers > 1`` timings
    share the machine, so compare run times only between sweeps run with the same ``workers``.

    Parameters
    ----------
    config : SweepConfig
    workers : int
    executor : concurrent.futures.Executor, optional

    Yields
    ------
    TrialResult
        One per trial, in trial order.
    """
    trials = config.trials()
    where = "the given executor" if executor is not None else f"{max(workers, 1)} worker(s)"
    logger.info("sweep %s: %d trials on %s", config.domain, len(trials), where)
    finished: dict[int, TrialResult] = {}
    next_index = 0
    for index, result in run_trials(trials, workers=workers, executor=executor):
        finished[index] = result
        while next_index in finished:
            yield finished.pop(next_index)
            next_index += 1


#: The grouping of :func:`summarize`: one summary row per distinct value of these fields.
GROUP_BY = ("method", "occlusion", "noise", "trajectories", "length", "learner")


def _group_rng(seed: int, key: tuple) -> np.random.Generator:
    """The bootstrap generator of one group: from the sweep seed and the group's data point
    (occlusion, noise, trajectories, length) only. So a group's interval does not depend on
    which other groups were swept, and every method and learner setting at a point resamples
    the same batches (their intervals are paired, like their data)."""
    fields = dict(zip(GROUP_BY, key, strict=True))
    words = [zlib.crc32(repr(fields[k]).encode())
             for k in ("occlusion", "noise", "trajectories", "length")]
    return np.random.default_rng(np.random.SeedSequence([seed, *words]))


def summarize(
    results: Iterable[TrialResult],
    *,
    seed: int = 0,
    n_resamples: int = N_RESAMPLES,
    confidence: float = CONFIDENCE,
) -> list[dict]:
    """Per (method, occlusion, noise, trajectories, length, learner setting): means over batches
    with percentile-bootstrap intervals over batches.

    Each row holds the group's fields, ``learner_beta``, ``batches`` (n), ``normalized_ile_mean``
    and ``normalized_ile_ci_low``/``_high``, ``exact_policy_rate`` and
    ``exact_policy_ci_low``/``_high``, ``ile_mean``, ``ile_std``, ``ile_ci_low``/``_high``,
    ``seconds_mean``, ``seconds_std``, ``seconds_ci_low``/``_high``, and ``converged`` (count).
    Intervals are reproducible from ``seed`` (the sweep's seed).

    Parameters
    ----------
    results : iterable of TrialResult
    seed : int
        The sweep's seed, from which each group's bootstrap is drawn.
    n_resamples : int
        Bootstrap resamples.
    confidence : float
        The intervals' level, e.g. 0.95.

    Returns
    -------
    list of dict
        One row per group, in the order of the learners' registry, then the point.
    """
    table: dict[tuple, list[TrialResult]] = {}
    for r in results:
        table.setdefault(tuple(getattr(r, k) for k in GROUP_BY), []).append(r)
    rows = []
    for key, rs in sorted(table.items(), key=lambda kv: _sort_key(kv[0], kv[1][0])):
        rng = _group_rng(seed, key)

        def ci(values, rng=rng):
            return bootstrap_ci(values, np.mean, n_resamples=n_resamples,
                                confidence=confidence, rng=rng)

        ile = np.array([r.ile for r in rs])
        nile = np.array([r.normalized_ile for r in rs])
        exact = np.array([r.exact_policy for r in rs], dtype=float)
        sec = np.array([r.seconds for r in rs])
        row = dict(zip(GROUP_BY, key, strict=True))
        nile_ci, exact_ci, ile_ci, sec_ci = ci(nile), ci(exact), ci(ile), ci(sec)
        row.update({
            "learner_beta": float(rs[0].learner_beta), "batches": len(rs),
            "normalized_ile_mean": float(nile.mean()),
            "normalized_ile_ci_low": nile_ci[0], "normalized_ile_ci_high": nile_ci[1],
            "exact_policy_rate": float(exact.mean()),
            "exact_policy_ci_low": exact_ci[0], "exact_policy_ci_high": exact_ci[1],
            "ile_mean": float(ile.mean()), "ile_std": float(ile.std()),
            "ile_ci_low": ile_ci[0], "ile_ci_high": ile_ci[1],
            "seconds_mean": float(sec.mean()), "seconds_std": float(sec.std()),
            "seconds_ci_low": sec_ci[0], "seconds_ci_high": sec_ci[1],
            "converged": int(sum(r.converged for r in rs)),
        })
        rows.append(row)
    return rows


def _sort_key(key: tuple, first: TrialResult) -> tuple:
    method, *rest = key
    order = list(LEARNERS).index(method) if method in LEARNERS else len(LEARNERS)
    *point, learner = rest
    return (order, method, *point, first.learner_beta, learner)


def result_rows(results: Sequence[TrialResult]) -> list[dict]:
    """The results as rows of a table (``results.csv``).

    Parameters
    ----------
    results : sequence of TrialResult

    Returns
    -------
    list of dict
        Each result's fields by name.
    """
    return [asdict(r) for r in results]
