"""Sweeps of the paper's experiments: ILE and run time over occlusion x noise x batches.

A sweep is a list of :class:`Trial` (method, occlusion, noise, batch); each trial samples its
own batch of demonstrations from a seed derived from (sweep seed, occlusion, noise, batch), so
every method sees the same data and any trial can be re-run alone. Trials are independent and
run on a process pool.
"""

from __future__ import annotations

import logging
import time
import warnings
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass

import numpy as np

from irl.domains import Domain, forestworld, onion_sorting
from irl.exceptions import ConvergenceWarning
from irl.learners.registry import LEARNERS, make_estimator
from irl.metrics import inverse_learning_error, normalized_inverse_learning_error

__all__ = [
    "DOMAINS",
    "METHODS",
    "SweepConfig",
    "Trial",
    "TrialResult",
    "make_estimator",
    "run_sweep",
    "run_trial",
    "summarize",
]

logger = logging.getLogger(__name__)

DOMAINS: dict[str, Callable[..., Domain]] = {
    "forestworld": forestworld,
    "sorting": onion_sorting,
}
#: The paper's learners, in registration order; a sweep may also name any learner registered
#: since (:func:`irl.learners.register_learner`; with ``workers > 1`` it must be registered on
#: import of a module the workers import too).
METHODS = tuple(LEARNERS)


@dataclass(frozen=True)
class SweepConfig:
    """What to sweep. ``points`` are the (occlusion, noise) pairs; each gets ``batches`` batches
    of ``trajectories`` demonstrations of ``length`` steps."""

    domain: str
    points: tuple[tuple[float, float], ...]
    methods: tuple[str, ...] = METHODS
    batches: int = 10
    trajectories: int = 10
    length: int = 20
    seed: int = 0

    def __post_init__(self) -> None:
        if self.domain not in DOMAINS:
            raise ValueError(f"domain must be one of {sorted(DOMAINS)}; got {self.domain!r}")
        unknown = [m for m in self.methods if m not in LEARNERS]
        if unknown:
            raise ValueError(f"methods must be among {tuple(LEARNERS)}; got {unknown}")
        for name in ("batches", "trajectories", "length"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1; got {getattr(self, name)}")
        for occ, noise in self.points:
            if not 0.0 <= occ < 1.0:
                raise ValueError(f"occlusion must be in [0, 1); got {occ}")
            if not 0.0 <= noise < 1.0:
                raise ValueError(f"noise must be in [0, 1); got {noise}")

    def trials(self) -> list[Trial]:
        return [
            Trial(self.domain, m, occ, noise, b, self.trajectories, self.length, self.seed)
            for occ, noise in self.points
            for b in range(self.batches)
            for m in self.methods
        ]


@dataclass(frozen=True)
class Trial:
    domain: str
    method: str
    occlusion: float
    noise: float
    batch: int
    trajectories: int
    length: int
    seed: int

    def data_seed(self) -> np.random.SeedSequence:
        """Seed of the batch's data: shared by all methods of one (occlusion, noise, batch)."""
        key = [self.seed, round(self.occlusion * 1000), round(self.noise * 1000), self.batch]
        return np.random.SeedSequence(key)


@dataclass(frozen=True)
class TrialResult:
    method: str
    occlusion: float
    noise: float
    batch: int
    ile: float
    normalized_ile: float
    seconds: float
    n_iter: int
    converged: bool


def run_trial(trial: Trial) -> TrialResult:
    """Sample the trial's batch, fit its method, and score it."""
    domain = DOMAINS[trial.domain](noise=trial.noise)
    data_rng = np.random.default_rng(trial.data_seed())
    demos, _ = domain.sample(trial.trajectories, trial.length, trial.occlusion, data_rng)
    est = make_estimator(trial.method, domain, seed=trial.batch)
    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ConvergenceWarning)
        est.fit(demos)
    seconds = time.perf_counter() - start
    converged = not any(issubclass(w.category, ConvergenceWarning) for w in caught)
    return TrialResult(
        method=trial.method,
        occlusion=trial.occlusion,
        noise=trial.noise,
        batch=trial.batch,
        ile=inverse_learning_error(domain.mdp, domain.true_theta, est.theta_),
        normalized_ile=normalized_inverse_learning_error(
            domain.mdp, domain.true_theta, est.theta_
        ),
        seconds=seconds,
        n_iter=int(est.n_iter_),
        converged=converged,
    )


def run_sweep(config: SweepConfig, *, workers: int = 1) -> Iterator[TrialResult]:
    """Run every trial of the sweep, yielding results as they finish (in trial order).

    ``workers > 1`` runs trials on a process pool; timings then share the machine, so compare
    run times only between sweeps run with the same ``workers``.
    """
    trials = config.trials()
    logger.info("sweep %s: %d trials on %d worker(s)", config.domain, len(trials), workers)
    if workers <= 1:
        yield from map(run_trial, trials)
        return
    with ProcessPoolExecutor(max_workers=workers) as pool:
        yield from pool.map(run_trial, trials, chunksize=1)


def summarize(results: Iterable[TrialResult]) -> list[dict]:
    """Mean and standard deviation of ILE and run time per (method, occlusion, noise)."""
    table: dict[tuple, list[TrialResult]] = {}
    for r in results:
        table.setdefault((r.method, r.occlusion, r.noise), []).append(r)
    rows = []
    for (method, occ, noise), rs in sorted(table.items()):
        ile = np.array([r.ile for r in rs])
        nile = np.array([r.normalized_ile for r in rs])
        sec = np.array([r.seconds for r in rs])
        rows.append({
            "method": method, "occlusion": occ, "noise": noise, "batches": len(rs),
            "ile_mean": float(ile.mean()), "ile_std": float(ile.std()),
            "normalized_ile_mean": float(nile.mean()),
            "seconds_mean": float(sec.mean()), "seconds_std": float(sec.std()),
            "converged": int(sum(r.converged for r in rs)),
        })
    return rows


def result_rows(results: Sequence[TrialResult]) -> list[dict]:
    return [asdict(r) for r in results]
