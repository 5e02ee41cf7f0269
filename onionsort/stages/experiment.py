"""Stage ``experiment``: the paper's sweeps (Fig. 1b-d on Forestworld, Fig. 3a-b on sorting), and
data-efficiency and misspecified-beta sweeps with bootstrap intervals.

Writes ``results.csv`` (one row per method, occlusion, noise, number of demonstrations, length,
learner setting and batch), ``summary.json`` (means with 95% percentile-bootstrap intervals over
batches) and the plots into the run folder; rows go to ``results.csv.partial`` as they finish.

Example::

    from onionsort.stages import ExperimentConfig, run_experiment
    summary = run_experiment(ExperimentConfig(domain="sorting", quick=True))
    summary = run_experiment(ExperimentConfig(
        domain="sorting", occlusion=(0.2,), noise=(0.3, 0.45), trajectories=(1, 2, 4, 8),
        learner_beta=("x0.25", "x1", "paper"), batches=20, out=Path("runs/efficiency")))
"""

from __future__ import annotations

import csv
import logging
from dataclasses import asdict, dataclass
from pathlib import Path

from onionsort.stages.base import check_output_folder, log_config, write_json

__all__ = ["CSV_COLUMNS", "ExperimentConfig", "format_table", "parse_list", "run_experiment"]

logger = logging.getLogger(__name__)

#: The paper's sweeps: (occlusion, noise) points per domain.
PAPER_POINTS = {
    # Fig. 1b: occlusion 10-40% at noise 0 and 30%; Fig. 1c: noise 20-45% without occlusion.
    "forestworld": [(o, n) for n in (0.0, 0.3) for o in (0.1, 0.2, 0.3, 0.4)]
    + [(0.0, n) for n in (0.2, 0.25, 0.3, 0.35, 0.4, 0.45)],
    # Fig. 3a-b: occlusion at the estimated 30% noise.
    "sorting": [(o, 0.3) for o in (0.0, 0.1, 0.2, 0.3, 0.4)],
}
QUICK_POINTS = {
    "forestworld": [(0.1, 0.3), (0.3, 0.3), (0.0, 0.2), (0.0, 0.4)],
    "sorting": [(0.1, 0.3), (0.3, 0.3)],
}
CSV_COLUMNS = ["method", "occlusion", "noise", "trajectories", "length", "learner",
               "learner_beta", "batch", "ile", "seconds", "normalized_ile", "exact_policy",
               "n_iter", "converged"]


def parse_list(text: str, name: str, kind: str = "int") -> tuple:
    """A comma-separated option value as a tuple: ``kind`` ``"int"`` (positive integers) or
    ``"learner"`` (betas, factors ``x0.5`` or ``paper``). A ``ValueError`` names the option."""
    from irl.experiments import parse_learner_setting

    items = [x.strip() for x in str(text).split(",") if x.strip()]
    if not items:
        raise ValueError(f"--{name} must list at least one value; got {text!r}")
    if kind == "learner":
        return tuple(parse_learner_setting(x) for x in items)
    try:
        values = tuple(int(x) for x in items)
    except ValueError:
        values = ()
    if not values or min(values) < 1:
        raise ValueError(f"--{name} must be comma-separated integers >= 1, e.g. 1,2,4,8; "
                         f"got {text!r}")
    return values


@dataclass(frozen=True)
class ExperimentConfig:
    """A sweep as asked for; None fields take the paper's (or the quick) defaults.

    Attributes
    ----------
    domain : str
        ``forestworld`` or ``sorting``.
    occlusion, noise : tuple of float or None
        The grid; both None: the paper's points for the domain.
    batches : int or None
        Batches per point.
    trajectories, length : int, tuple of int, or None
        Demonstrations per batch, steps per demonstration; several values sweep them.
    learner_beta : tuple of str or None
        Learner settings (``irl.experiments.parse_learner_setting``): betas, factors of the
        domain's beta (``x0.5``) or ``paper``; None: the domain's true beta.
    methods : tuple of str
    seed, workers : int
    quick : bool
        A small sweep that takes seconds.
    out : Path or None
        Run folder (default ``runs/experiment-DOMAIN``).
    """

    domain: str
    occlusion: tuple[float, ...] | None = None
    noise: tuple[float, ...] | None = None
    batches: int | None = None
    trajectories: int | tuple[int, ...] | None = None
    length: int | tuple[int, ...] | None = None
    learner_beta: tuple[str, ...] | None = None
    methods: tuple[str, ...] = ("mmap-birl", "map-birl", "hidden-data-em", "maxent")
    seed: int = 0
    workers: int = 2
    quick: bool = False
    out: Path | None = None

    def sweep(self):
        """The :class:`irl.experiments.SweepConfig` this resolves to."""
        from irl.experiments import SweepConfig

        if self.occlusion is not None or self.noise is not None:
            occ = self.occlusion if self.occlusion is not None else (0.0,)
            noise = self.noise if self.noise is not None else (0.3,)
            points = [(o, n) for n in noise for o in occ]
        else:
            points = (QUICK_POINTS if self.quick else PAPER_POINTS)[self.domain]
        defaults = {"batches": 3 if self.quick else 10, "trajectories": 10,
                    "length": 15 if self.domain == "forestworld" else 20}
        return SweepConfig(
            domain=self.domain, points=tuple(points), methods=tuple(self.methods),
            batches=self.batches or defaults["batches"],
            trajectories=self.trajectories or defaults["trajectories"],
            length=self.length or defaults["length"],
            learners=tuple(self.learner_beta or ("x1",)), seed=self.seed)

    @property
    def folder(self) -> Path:
        return self.out or Path("runs") / f"experiment-{self.domain}"


def run_experiment(config: ExperimentConfig) -> dict:
    """Run the sweep; write the CSV, ``summary.json`` and plots; return the summary."""
    from tqdm import tqdm

    from irl.experiments import CONFIDENCE, N_RESAMPLES, run_sweep, summarize
    from onionsort.plots import plot_sweep

    sweep = config.sweep()
    log_config("experiment", sweep)
    out = check_output_folder(config.folder)
    trials = sweep.trials()
    results = []
    partial = out / "results.csv.partial"
    with partial.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=CSV_COLUMNS)
        writer.writeheader()
        for r in tqdm(run_sweep(sweep, workers=config.workers), total=len(trials),
                      desc=f"{config.domain} sweep", unit="fit"):
            results.append(r)
            writer.writerow(asdict(r))
            fh.flush()
    partial.replace(out / "results.csv")
    points = summarize(results, seed=sweep.seed)
    summary = {"config": asdict(sweep), "workers": config.workers,
               "bootstrap": {"method": "percentile, resampling batches",
                             "n_resamples": N_RESAMPLES, "confidence": CONFIDENCE,
                             "seed": sweep.seed},
               "points": points}
    write_json(out / "summary.json", summary)
    summary["plots"] = [str(p) for p in plot_sweep(results, out, title=config.domain,
                                                   points=points)]
    return summary


def format_table(points: list[dict]) -> str:
    """The summary's points as a fixed-width table (intervals are 95% bootstrap over batches)."""
    lines = [f"{'method':<15}{'learner':>8}{'occl':>6}{'noise':>6}{'demos':>6}{'len':>5}"
             f"{'nILE % [95% CI]':>26}{'exact [95% CI]':>22}{'ILE mean':>10}{'seconds':>9}"]
    for p in points:
        nile = (f"{p['normalized_ile_mean']:.3f} [{p['normalized_ile_ci_low']:.3f}, "
                f"{p['normalized_ile_ci_high']:.3f}]")
        exact = (f"{p['exact_policy_rate']:.2f} [{p['exact_policy_ci_low']:.2f}, "
                 f"{p['exact_policy_ci_high']:.2f}]")
        lines.append(
            f"{p['method']:<15}{p['learner']:>8}{p['occlusion']:>6.2f}{p['noise']:>6.2f}"
            f"{p['trajectories']:>6d}{p['length']:>5d}{nile:>26}{exact:>22}"
            f"{p['ile_mean']:>10.2f}{p['seconds_mean']:>9.3f}"
        )
    return "\n".join(lines)
