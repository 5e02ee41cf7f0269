"""Stage ``experiment``: the paper's sweeps (Fig. 1b-d on Forestworld, Fig. 3a-b on sorting), and
data-efficiency and misspecified-beta sweeps with bootstrap intervals.

Writes ``results.csv`` (one row per method, occlusion, noise, number of demonstrations, length,
learner setting and batch), ``summary.json`` (means with 95% percentile-bootstrap intervals over
batches), the plots and ``report.md`` (:mod:`onionsort.stages.report`) into the run folder.
Rows go to ``results.csv.partial`` as trials finish, beside ``results.csv.partial.json`` (the
sweep they belong to); ``resume=True`` keeps those rows
and runs only the missing trials, so the final ``results.csv`` (rows in trial order) equals that
of an uninterrupted run, timings aside. Trials run on the stages' executor
(:class:`~onionsort.stages.parallel.ParallelOptions`): a local process pool
(``executor="local"``; ``"process"``, its former name, is taken too) or Ray tasks
(``executor="ray"``: the Ray instance this process already joined, else ``ray_address``, else
``RAY_ADDRESS``, else a new local instance of ``workers`` CPUs); both give the same rows.
``backend`` picks the forward-backward kernels of MMAP-BIRL and ``bc-em``: numpy, or numba,
which gives the same results to rounding (HiddenDataEM's E-step, whose policy is time-indexed,
always runs numpy). Each row records the backend of the sweep that ran it (``summary.json`` their
counts), and a sweep may be resumed with the other one: the kept rows keep theirs.

Example::

    from onionsort.stages import ExperimentConfig, run_experiment
    summary = run_experiment(ExperimentConfig(domain="sorting", quick=True))
    summary = run_experiment(ExperimentConfig(
        domain="sorting", occlusion=(0.2,), noise=(0.3, 0.45), trajectories=(1, 2, 4, 8),
        learner_beta=("x0.25", "x1", "paper"), batches=20, out=Path("runs/efficiency")))
    summary = run_experiment(ExperimentConfig(domain="forestworld", executor="ray",
                                              ray_address="auto", resume=True))
    summary = run_experiment(ExperimentConfig(domain="sorting", quick=True, backend="numba"))
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import json
import logging
from collections import Counter
from dataclasses import asdict
from pathlib import Path

from onionsort.configs.experiment import ExperimentConfig
from onionsort.stages.base import check_output_folder, log_config, write_json
from onionsort.stages.parallel import RayExecutor
from onionsort.stages.report import ReportConfig, report

__all__ = ["CSV_COLUMNS", "ExperimentConfig", "format_table", "parse_list",
           "run_experiment"]

logger = logging.getLogger(__name__)

CSV_COLUMNS = ["method", "occlusion", "noise", "trajectories", "length", "learner",
               "learner_beta", "batch", "ile", "seconds", "normalized_ile", "exact_policy",
               "n_iter", "converged", "backend"]
#: The columns that name a trial (all but its scores): a row's identity when resuming.
TRIAL_COLUMNS = ("method", "occlusion", "noise", "trajectories", "length", "learner", "batch")
PARTIAL = "results.csv.partial"
#: Beside the partial rows: the sweep they belong to, checked by ``resume``.
PARTIAL_SWEEP = "results.csv.partial.json"


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


def run_experiment(config: ExperimentConfig) -> dict:
    """Run the sweep; write the CSV, ``summary.json``, plots and ``report.md``; return the
    summary (with the paths of the plots, ``plots``, and of the report, ``report``).

    A ``results.csv.partial`` left in the folder by an interrupted run is continued with
    ``resume=True`` (refused if it is from a sweep with other parameters) and is otherwise
    refused rather than overwritten.
    """
    from tqdm import tqdm

    from irl.experiments import CONFIDENCE, N_RESAMPLES, run_trials, summarize
    from onionsort.plots import plot_sweep

    sweep = config.sweep()
    log_config("experiment", sweep)
    out = check_output_folder(config.folder)
    trials = sweep.trials()
    partial, sweep_doc = out / PARTIAL, _sweep_doc(sweep)
    if config.resume and partial.exists():
        done = _read_partial(out, sweep_doc, trials)
        logger.info("resuming %s: %d of %d trials already done", partial, len(done), len(trials))
        other = sorted({r.backend for r in done.values()} - {sweep.backend})
        if other:
            logger.info("the kept trials ran on backend %s, the rest run on %s (equal to "
                        "rounding; each row of results.csv names its backend)",
                        " and ".join(other), sweep.backend)
    elif partial.exists():
        raise FileExistsError(f"{partial} holds the rows of an interrupted sweep; continue it "
                              "with --resume, or delete it to start over")
    else:
        if config.resume:
            logger.warning("nothing to resume in %s; running the whole sweep", out)
        done = {}
    results = dict(done)
    pending = [i for i in range(len(trials)) if i not in done]
    with _executor(config, pending) as executor:
        if not done and not partial.exists():
            write_json(out / PARTIAL_SWEEP, sweep_doc)
            _write_rows(partial, [])
        try:
            with partial.open("a", newline="") as fh:
                writer = csv.DictWriter(fh, fieldnames=CSV_COLUMNS)
                for k, r in tqdm(run_trials([trials[i] for i in pending],
                                            workers=config.n_workers, executor=executor),
                                 initial=len(done), total=len(trials),
                                 desc=f"{config.domain} sweep", unit="fit"):
                    results[pending[k]] = r
                    writer.writerow(asdict(r))
                    fh.flush()
        except BaseException:
            logger.warning("sweep stopped: %d of %d trials are kept in %s; continue with "
                           "--resume", len(results), len(trials), partial)
            raise
    ordered = [results[i] for i in range(len(trials))]
    _write_rows(out / "results.csv", ordered)
    partial.unlink()
    (out / PARTIAL_SWEEP).unlink(missing_ok=True)
    points = summarize(ordered, seed=sweep.seed)
    summary = {"config": asdict(sweep), "workers": config.n_workers,
               "executor": config.executor,
               "resumed_trials": len(done),
               "trial_backends": dict(sorted(Counter(r.backend for r in ordered).items())),
               "bootstrap": {"method": "percentile, resampling batches",
                             "n_resamples": N_RESAMPLES, "confidence": CONFIDENCE,
                             "seed": sweep.seed},
               "points": points}
    write_json(out / "summary.json", summary)
    summary["plots"] = [str(p) for p in plot_sweep(ordered, out, title=config.domain,
                                                   points=points)]
    summary["report"] = str(report(ReportConfig(run=out)))
    return summary


def _sweep_doc(sweep) -> dict:
    """The sweep's parameters that a resumed run must share, as JSON reads them back (lists,
    not tuples). The backend is not among them: it changes how the trials are computed, not
    their results (to rounding), and each row records its own."""
    config = {k: v for k, v in asdict(sweep).items() if k != "backend"}
    return json.loads(json.dumps({"columns": CSV_COLUMNS, "config": config}))


def _write_rows(path: Path, results) -> None:
    """``results`` as CSV rows under the header, through a temporary name."""
    tmp = path.with_name(path.name + ".tmp")
    try:
        with tmp.open("w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=CSV_COLUMNS)
            writer.writeheader()
            writer.writerows(asdict(r) for r in results)
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)


def _read_partial(out: Path, sweep_doc: dict, trials) -> dict:
    """The finished trials of ``out``'s partial rows, by position in ``trials``; the partial
    file is rewritten without a last row cut short by the interruption."""
    from irl.experiments import TrialResult

    partial, meta = out / PARTIAL, out / PARTIAL_SWEEP
    if not meta.exists():
        raise ValueError(f"cannot resume: {partial} has no {PARTIAL_SWEEP} naming its sweep; "
                         "delete it to start over")
    stored = json.loads(meta.read_text())
    if stored != sweep_doc:
        was, now = stored.get("config", {}), sweep_doc["config"]
        diffs = [f"{k} {was.get(k)!r} there, {now[k]!r} here" for k in now
                 if was.get(k) != now[k]]
        if stored.get("columns") != sweep_doc["columns"]:
            diffs.append(f"columns {stored.get('columns')!r} there, {CSV_COLUMNS!r} here")
        raise ValueError(f"cannot resume: {partial} is from another sweep ({'; '.join(diffs)}); "
                         "use the same options or another --out")
    kinds = {f.name: f.type for f in dataclasses.fields(TrialResult)}
    convert = {"int": int, "float": float, "str": str,
               "bool": lambda text: {"True": True, "False": False}[text]}
    position = {_trial_key(t): i for i, t in enumerate(trials)}
    with partial.open(newline="") as fh:
        reader = csv.DictReader(fh)
        if reader.fieldnames != CSV_COLUMNS:
            raise ValueError(f"cannot resume: the header of {partial} is {reader.fieldnames}, "
                             f"not {CSV_COLUMNS}")
        rows = list(reader)
    done: dict[int, TrialResult] = {}
    for n, row in enumerate(rows):
        try:
            result = TrialResult(**{k: convert[kinds[k]](row[k]) for k in CSV_COLUMNS})
        except (KeyError, TypeError, ValueError):
            if n == len(rows) - 1:  # the row being written when the run was stopped
                logger.warning("dropping the incomplete last row of %s", partial)
                break
            raise ValueError(f"cannot resume: row {n + 2} of {partial} is not a result row; "
                             "delete the file to start over") from None
        index = position.get(_trial_key(result))
        if index is None:
            raise ValueError(f"cannot resume: row {n + 2} of {partial} is not a trial of this "
                             "sweep; delete the file to start over")
        done.setdefault(index, result)
    _write_rows(partial, [done[i] for i in sorted(done)])
    return done


def _trial_key(item) -> tuple:
    return tuple(getattr(item, k) for k in TRIAL_COLUMNS)


def _executor(config: ExperimentConfig, pending: list[int]):
    """The executor of ``config`` for ``pending`` trials: None (``run_trials``' own process
    pool) or a Ray executor, as a context manager that shuts it down."""
    if config.executor != "ray" or not pending:
        return contextlib.nullcontext()
    return RayExecutor(config.ray_address, config.n_workers)


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
