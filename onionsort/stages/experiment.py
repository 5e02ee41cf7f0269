"""Stage ``experiment``: the paper's sweeps (Fig. 1b-d on Forestworld, Fig. 3a-b on sorting).

Writes ``results.csv`` (one row per method, occlusion, noise and batch), ``summary.json`` and
the plots into the run folder; rows go to ``results.csv.partial`` as they finish.

Example::

    from onionsort.stages import ExperimentConfig, run_experiment
    summary = run_experiment(ExperimentConfig(domain="sorting", quick=True))
"""

from __future__ import annotations

import csv
import logging
from dataclasses import asdict, dataclass
from pathlib import Path

from onionsort.stages.base import check_output_folder, log_config, write_json

__all__ = ["CSV_COLUMNS", "ExperimentConfig", "format_table", "run_experiment"]

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
CSV_COLUMNS = ["method", "occlusion", "noise", "batch", "ile", "seconds",
               "normalized_ile", "n_iter", "converged"]


@dataclass(frozen=True)
class ExperimentConfig:
    """A sweep as asked for; None fields take the paper's (or the quick) defaults.

    Attributes
    ----------
    domain : str
        ``forestworld`` or ``sorting``.
    occlusion, noise : tuple of float or None
        The grid; both None: the paper's points for the domain.
    batches, trajectories, length : int or None
        Batches per point, demonstrations per batch, steps per demonstration.
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
    trajectories: int | None = None
    length: int | None = None
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
            length=self.length or defaults["length"], seed=self.seed)

    @property
    def folder(self) -> Path:
        return self.out or Path("runs") / f"experiment-{self.domain}"


def run_experiment(config: ExperimentConfig) -> dict:
    """Run the sweep; write the CSV, ``summary.json`` and plots; return the summary."""
    from tqdm import tqdm

    from irl.experiments import run_sweep, summarize
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
    summary = {"config": asdict(sweep), "workers": config.workers,
               "points": summarize(results)}
    write_json(out / "summary.json", summary)
    summary["plots"] = [str(p) for p in plot_sweep(results, out, title=config.domain)]
    return summary


def format_table(points: list[dict]) -> str:
    """The summary's points as a fixed-width table."""
    lines = [f"{'method':<16}{'occlusion':>10}{'noise':>7}{'ILE mean':>12}{'ILE std':>10}"
             f"{'nILE %':>9}{'seconds':>10}"]
    for p in points:
        lines.append(
            f"{p['method']:<16}{p['occlusion']:>10.2f}{p['noise']:>7.2f}{p['ile_mean']:>12.2f}"
            f"{p['ile_std']:>10.2f}{p['normalized_ile_mean']:>9.3f}{p['seconds_mean']:>10.3f}"
        )
    return "\n".join(lines)
