"""Stage ``demo``: the whole job on built-in defaults, into one run folder.

1. record 12 sessions of a person sorting onions (20 steps each; the passer-by occludes about 4
   of them) to MCAP;
2. perceive them with the shipped detector and state classifier, and log the sessions with
   what perception made of them to one Rerun recording (``sessions.rrd``);
3. calibrate the observation model on freshly rendered held-out frames;
4. learn the sorter's reward with MMAP-BIRL, with MAP-BIRL (the same model reading the
   observations at face value: the ablation that shows what modelling observer noise is worth)
   and with HiddenDataEM (``methods`` picks others: any registered learner, e.g. behaviour
   cloning's ``bc`` and ``bc-em``, which copy the sorter's actions and learn no reward);
5. let the Sawyer sort 50 onions (30 blemished) with each learned policy, inspection by the
   detector;
6. write ``results.json`` with the paper's Table 1 beside ours (:func:`table`), and
   ``report.md`` (:mod:`onionsort.stages.report`): the settings, Table 1, the calibration, the
   learning curves and the recordings, with a precision/recall figure.

``repeats`` runs steps 1, 2, 4 and 5 again with other seeds (repeat ``k`` uses seed
``seed + k``; one calibration serves all). ``results.json`` then holds the counts summed over
the repeats, each repeat's own, and 95% intervals of precision and recall from a two-level
bootstrap (repeats, then onions within a repeat), so both the spread between learned policies
and the finite line-up count. ``quick`` runs the pipeline small (4 sessions, 10 onions): the
end-to-end smoke test.

Every finished stage leaves a marker ``OUT/progress/STAGE.json`` (written atomically, after the
stage's outputs), and ``OUT/progress/config.json`` records the settings the run was started
with. The stages: ``heldout`` (the held-out frames), ``calibrate``, and per repeat ``k``
``record-k``, ``perceive-k``, ``learn-k-METHOD`` and ``evaluate-k-METHOD``. ``resume``
continues an interrupted demo in its folder: a stage with a marker is skipped (its outputs are
complete), the others run again from their own seeds: an interrupted recording keeps its
complete sessions (``record --resume``), perception takes the sessions not perceived yet, and a
stage's half-written folder is replaced. ``results.json`` is built from the markers and the
files on disk in both cases, so a resumed demo's is the uninterrupted one's, timings aside
(``seconds`` and ``learn_seconds`` are the time the run that did the work took). ``connect``
streams the Rerun recordings of the stages that run to a viewer on another machine, in
addition to their ``.rrd`` files.

Example::

    from onionsort.stages import DemoConfig, demo
    results = demo(DemoConfig(out=Path("runs/demo-quick"), quick=True))
"""

from __future__ import annotations

import dataclasses
import json
import logging
import shutil
import time
from collections.abc import Callable
from pathlib import Path

from onionsort.configs.common import sorting_threshold
from onionsort.configs.demo import DemoConfig
from onionsort.stages.base import check_output_folder, log_config, write_json
from onionsort.stages.calibrate import CalibrateConfig, calibrate
from onionsort.stages.dataset import DatasetConfig, make_dataset
from onionsort.stages.evaluate import EvaluateConfig, evaluate
from onionsort.stages.learn import BAYESIAN_METHODS, SWAP_METHOD, LearnConfig, learn
from onionsort.stages.models import PerceptionModels
from onionsort.stages.parallel import ParallelOptions, run_pieces
from onionsort.stages.perceive import PerceiveConfig, perceive
from onionsort.stages.record import RecordConfig, record
from onionsort.stages.report import ReportConfig, report
from onionsort.stages.table1 import METHODS, PAPER_TABLE_1, table

__all__ = ["METHODS", "PAPER_TABLE_1", "DemoConfig", "demo", "table"]

logger = logging.getLogger(__name__)

#: The demo's line-up and recording sizes, full and quick.
SIZES = {False: {"sessions": 12, "steps": 20, "heldout": 1500, "onions": 50, "blemished": 30},
         True: {"sessions": 4, "steps": 12, "heldout": 360, "onions": 10, "blemished": 6}}


def demo(config: DemoConfig) -> dict:
    """Run the whole job (with ``config.resume``, the stages not finished yet); write
    ``config.out/results.json`` and ``config.out/report.md``; return the results."""
    from state_abstraction.calibration import load_calibration

    log_config("demo", config)
    start = time.perf_counter()
    out = config.out
    size = dict(SIZES[config.quick])
    if config.sessions is not None:
        size["sessions"] = config.sessions
    if config.connect is not None:
        from recordings.rerun.common import reach_viewer

        reach_viewer(config.connect)  # a wrong address fails now, not after the first stage
    progress = _Progress(out, _settings(config, size), resume=config.resume)
    if config.resume and (out / "results.json").is_file():
        logger.info("%s holds a finished demo; nothing to resume", out)
        report(ReportConfig(run=out))
        return json.loads((out / "results.json").read_text())
    progress.start()
    options = config.parallel_options()
    # on one worker the models load here; on more, the workers alone load torch and them
    here = config.executor == "local" and config.n_workers == 1
    models = PerceptionModels.load_cached(config.models, config.device) if here else None
    data = out / "heldout"
    progress.run("heldout", lambda: dataclasses.asdict(make_dataset(DatasetConfig(
        out=data, frames=size["heldout"], seed=config.seed + 1000, robot_onions=0,
        difficulty=config.difficulty, rot_labels=False, executor=config.executor,
        workers=config.workers, ray_address=config.ray_address))), clear=data)
    calibration_path = out / "calibration" / "calibration.json"

    def calibrate_stage() -> dict:
        _, metrics = calibrate(CalibrateConfig(data=data, split="all", out=out / "calibration",
                                               models=config.models, device=config.device,
                                               **dataclasses.asdict(options)), models)
        return {"n_steps": metrics["n_steps"]}

    measured = progress.run("calibrate", calibrate_stage, clear=out / "calibration")
    calibration = load_calibration(calibration_path)
    logger.info("calibrated on %d held-out steps: state error rate %.3f, (state, action) "
                "error rate %.3f", measured["n_steps"], calibration.state_error_rate,
                calibration.pair_error_rate)
    # the repeats' sessions, then every (repeat, method)'s learning and sorting, as pieces
    folders = [out if config.repeats == 1 else out / f"repeat_{k}" for k in range(config.repeats)]
    spread = config.executor == "ray" or config.repeats >= config.n_workers
    inner = ParallelOptions(workers=1) if spread else options
    sessions: list[list[Path]] = [[] for _ in folders]
    for k, paths in run_pieces(
            _sessions_piece, [(progress, k, folders[k], config.seed + k, size, config, inner)
                              for k in range(config.repeats)],
            options if spread else ParallelOptions(workers=1),
            names=[f"the sessions of repeat {k}" for k in range(config.repeats)],
            desc="demo: record and perceive", unit="repeat"):
        sessions[k] = paths
    jobs = [(k, method) for k in range(config.repeats) for method in config.methods]
    scored: dict[tuple[int, str], dict] = {}
    for j, result in run_pieces(
            _method_piece, [(progress, k, method, sessions[k], calibration_path,
                             folders[k] / method, config.seed + k, size, config)
                            for k, method in jobs], options,
            names=[f"{method} of repeat {k}" for k, method in jobs],
            desc="demo: learn and sort", unit="method"):
        scored[jobs[j]] = result
    per_repeat = {m: [scored[(k, m)] for k in range(config.repeats)] for m in config.methods}
    results = {"methods": {m: _pooled(runs, config.seed) for m, runs in per_repeat.items()},
               "paper": PAPER_TABLE_1, "quick": config.quick, "seed": config.seed,
               "difficulty": config.difficulty, "repeats": config.repeats,
               "backends": sorted({r["backend"] for runs in per_repeat.values()
                                   for r in runs}),
               "sessions": size["sessions"],
               "onions": size["onions"], "blemished": size["blemished"],
               "state_error_rate": calibration.state_error_rate,
               "pair_error_rate": calibration.pair_error_rate,
               # whole held-out sessions whose good/blemished reads were mostly backwards
               "sessions_read_backwards": None if calibration.session_swaps is None else {
                   k: calibration.session_swaps[k] for k in ("sessions", "swapped")},
               "inspection": {"views": config.inspection_views,
                              "threshold": sorting_threshold(config.miss_cost,
                                                             config.waste_cost),
                              # the rule the evaluations used, as they recorded it
                              "fusion": json.loads((folders[0] / config.methods[0]
                                                    / "evaluation.json"
                                                    ).read_text())["fusion"]},
               "seconds": round(time.perf_counter() - start, 1)}
    if config.session_swaps:
        results["session_swaps"] = {"rate": calibration.session_swap_rate,
                                    **calibration.session_swaps}
    if config.defer_below is not None:
        results["defer_below"] = config.defer_below
        results["deferring"] = {m: _pooled([r["deferring"] for r in runs], config.seed)
                                for m, runs in per_repeat.items() if m in BAYESIAN_METHODS}
    write_json(out / "results.json", results)
    report(ReportConfig(run=out))
    return results


def _settings(config: DemoConfig, size: dict) -> dict:
    """What a resumed demo must share with the run it continues."""
    return {"seed": config.seed, "quick": config.quick,
            "models": None if config.models is None else str(config.models),
            "sessions": size["sessions"], "repeats": config.repeats,
            "difficulty": config.difficulty, "inspection_views": config.inspection_views,
            "miss_cost": config.miss_cost, "waste_cost": config.waste_cost,
            "fusion": config.fusion,
            **({"session_swaps": True} if config.session_swaps else {}),
            # recorded only when not the default, so a default demo's settings are as before
            **({} if config.methods == METHODS else {"methods": list(config.methods)}),
            **({} if config.defer_below is None else {
                "defer_below": config.defer_below, "posterior_method": config.posterior_method})}


class _Progress:
    """The finished stages of a demo, one marker file each under ``OUT/progress``.

    Opening it checks the run folder: a new demo needs an empty (or new) one; a resumed demo
    one whose ``progress/config.json`` holds the same settings.
    """

    def __init__(self, out: Path, settings: dict, *, resume: bool) -> None:
        self.out = Path(out)
        self.folder = self.out / "progress"
        self.settings = settings
        self.resume = resume
        if resume and self.out.is_dir() and any(self.out.iterdir()):
            self._check_settings()
        else:
            _check_new_folder(self.out)
        check_output_folder(self.out)

    def _check_settings(self) -> None:
        path = self.folder / "config.json"
        try:
            started = json.loads(path.read_text())
        except FileNotFoundError:
            raise ValueError(f"cannot resume: --out {self.out} holds no demo progress ({path} "
                             "is missing); choose a new --out") from None
        except json.JSONDecodeError as exc:
            raise ValueError(f"cannot resume: {path} is not JSON ({exc})") from None
        # both ways: a setting given only when asked for (--defer-below, --session-swaps) is
        # missing on one side when a run started with it is resumed without it
        differ = [f"{k} {started.get(k)!r} there, {self.settings.get(k)!r} now"
                  for k in dict.fromkeys([*self.settings, *started])
                  if started.get(k) != self.settings.get(k)]
        if differ:
            raise ValueError(f"cannot resume: --out {self.out} holds a demo started with other "
                             f"settings ({'; '.join(differ)}); resume with the settings it was "
                             "started with, or choose a new --out")

    def start(self) -> None:
        """Record the settings (a new demo), before any stage runs."""
        self.folder.mkdir(parents=True, exist_ok=True)
        if not (self.folder / "config.json").exists():
            write_json(self.folder / "config.json", self.settings)

    def marker(self, stage: str) -> Path:
        return self.folder / f"{stage}.json"

    def run(self, stage: str, work: Callable[[], dict], clear: Path | None = None) -> dict:
        """The result of ``stage``: read from its marker if it finished before, else ``work()``
        (after removing ``clear``, the stage's half-written folder, when resuming), recorded
        in a new marker. Both ways the result is what the marker holds."""
        path = self.marker(stage)
        if path.is_file():
            logger.info("demo: %s finished before; skipped", stage)
        else:
            if self.resume and clear is not None and clear.exists():
                logger.info("demo: %s was interrupted; its %s is written again", stage, clear)
                shutil.rmtree(clear)
            write_json(path, {"stage": stage, "result": work()})
        return json.loads(path.read_text())["result"]


def _sessions_piece(piece: tuple) -> list[Path]:
    """Record and perceive repeat ``k``'s sessions (two stages, each skipped if its marker
    says it finished); their paths. ``piece``: ``(progress, k, folder, seed, size, config,
    options)``, ``options`` the recording's and perception's own executor."""
    progress, k, folder, seed, size, config, options = piece
    recorded = progress.run(f"record-{k}", lambda: _record(folder, seed, size, config,
                                                           options))
    paths = [folder / "sessions" / name for name in recorded["sessions"]]
    progress.run(f"perceive-{k}", lambda: _perceive(paths, config, options,
                                                     folder / "sessions.rrd"))
    return paths


def _record(folder: Path, seed: int, size: dict, config: DemoConfig,
            options: ParallelOptions) -> dict:
    """Record a repeat's sessions into ``folder/sessions`` (their Rerun recording is written
    once they are perceived: :func:`_perceive`); with ``config.resume``, keep the complete
    ones an interrupted demo recorded."""
    paths = record(RecordConfig(out=folder / "sessions", sessions=size["sessions"],
                                steps_per_session=size["steps"], occlusion=0.2, seed=seed,
                                difficulty=config.difficulty, resume=config.resume,
                                executor=options.executor, workers=options.workers,
                                ray_address=options.ray_address))
    return {"sessions": [p.name for p in paths]}


def _perceive(paths: list[Path], config: DemoConfig, options: ParallelOptions,
              rrd: Path) -> dict:
    """Perceive the sessions of ``paths`` that hold no perception topics yet (all of them,
    unless an interrupted demo perceived some), then log them all to the Rerun recording
    ``rrd`` (and the viewer at ``config.connect``): what was recorded and what perception made
    of it, side by side."""
    from recordings import open_session
    from recordings.rerun import SessionLogger
    from recordings.rerun.common import rerun_targets

    todo = tuple(p for p in paths if open_session(p).perception_models is None)
    if todo:
        parallel = min(options.n_workers, len(todo)) > 1 or options.executor == "ray"
        perceive(PerceiveConfig(sessions=todo, models=config.models, device=config.device,
                                executor=options.executor, workers=options.workers,
                                ray_address=options.ray_address),
                 None if parallel else PerceptionModels.load_cached(config.models,
                                                                    config.device))
    with SessionLogger(rerun_targets(rrd, config.connect)) as log:
        for i, path in enumerate(paths):
            log.log_session(open_session(path), i)
    return {"perceived": [p.name for p in todo]}


def _method_piece(piece: tuple) -> dict:
    """Learn with one method and sort with its policy: ``piece`` is ``(progress, k, method,
    sessions, calibration, run_dir, seed, size, config)``."""
    progress, k, method, sessions, calibration, run_dir, seed, size, config = piece
    return _learn_and_sort(progress, k, method, sessions, calibration, run_dir, seed, size,
                           config, PerceptionModels.load_cached(config.models, config.device))


def _check_new_folder(out: Path) -> None:
    """The demo writes a whole run folder: refuse one that holds anything (a finished demo, or
    one stopped half way), and make sure a new one can be written, before any work starts."""
    if out.is_dir():
        held = sorted(p.name for p in out.iterdir())
        if held:
            if "results.json" in held:
                raise FileExistsError(f"--out {out} already holds a demo (results.json); "
                                      "choose a new --out (or remove the folder to run the "
                                      "demo there again)")
            raise FileExistsError(
                f"--out {out} already holds files of an earlier or interrupted run: "
                + ", ".join(held[:4]) + (", ..." if len(held) > 4 else "")
                + "; pass --resume to continue it, or choose a new --out")
    check_output_folder(out)


def _learn_and_sort(progress: _Progress, k: int, method: str, sessions, calibration: Path,
                    run_dir: Path, seed: int, size: dict, config: DemoConfig,
                    models: PerceptionModels) -> dict:
    """Learn with one method, let the Sawyer sort with its policy (two stages of repeat
    ``k``); one repeat's result."""
    deferring = config.defer_below is not None and method in BAYESIAN_METHODS

    def learn_stage() -> dict:
        t0 = time.perf_counter()
        learn(LearnConfig(sessions=tuple(sessions), calibration=calibration, out=run_dir,
                          method=method, seed=seed, overwrite=config.resume,
                          connect=config.connect, backend=config.backend, posterior=deferring,
                          posterior_method=config.posterior_method,
                          session_swaps=config.session_swaps and method == SWAP_METHOD))
        return {"learn_seconds": round(time.perf_counter() - t0, 3)}

    def evaluate_stage(defer_below: float | None = None) -> dict:
        result, _ = evaluate(EvaluateConfig(run=run_dir, onions=size["onions"],
                                            blemished=size["blemished"], seed=seed,
                                            models=config.models,
                                            difficulty=config.difficulty,
                                            connect=config.connect,
                                            inspection_views=config.inspection_views,
                                            miss_cost=config.miss_cost,
                                            waste_cost=config.waste_cost,
                                            fusion=config.fusion, defer_below=defer_below,
                                            out=None if defer_below is None
                                            else run_dir / "deferring"), models)
        return {"tp": result.tp, "fp": result.fp, "tn": result.tn, "fn": result.fn,
                "precision": result.precision, "recall": result.recall,
                "undecided": result.undecided, "deferred": result.deferred}

    learned = progress.run(f"learn-{k}-{method}", learn_stage)
    scored = progress.run(f"evaluate-{k}-{method}", evaluate_stage)
    model = json.loads((run_dir / "model.json").read_text())
    one = {"seed": seed, **{c: scored[c] for c in ("tp", "fp", "tn", "fn", "precision",
                                                    "recall")},
           "learn_seconds": learned["learn_seconds"], "backend": model.get("backend", "numpy"),
           "theta": model["theta"], **_ile(model), "undecided": scored["undecided"]}
    if deferring:
        one["posterior"] = model["posterior"]
        one["deferring"] = progress.run(f"evaluate-deferring-{k}-{method}",
                                        lambda: evaluate_stage(config.defer_below))
    return one


def _pooled(runs: list[dict], seed: int) -> dict:
    """Counts summed over the repeats, precision and recall of the sums with their 95%
    intervals, the mean ILE, and every repeat's own result."""
    import numpy as np

    counts = np.array([[r["tp"], r["fp"], r["tn"], r["fn"]] for r in runs])
    tp, fp, tn, fn = (int(c) for c in counts.sum(axis=0))
    (p_lo, p_hi), (r_lo, r_hi) = precision_recall_intervals(counts, seed=seed)
    pooled = {"tp": tp, "fp": fp, "tn": tn, "fn": fn,
              "precision": tp / (tp + fp) if tp + fp else 0.0,
              "recall": tp / (tp + fn) if tp + fn else 0.0,
              "precision_ci": [p_lo, p_hi], "recall_ci": [r_lo, r_hi], "per_repeat": runs}
    for key in ("ile", "normalized_ile"):
        if all(key in r for r in runs):
            pooled[key] = float(np.mean([r[key] for r in runs]))
    if all("deferred" in r for r in runs):
        deferred = sum(r.get("deferred", 0) for r in runs)
        pooled["deferred"] = deferred
        pooled["deferral_rate"] = deferred / (deferred + tp + fp + tn + fn)
    return pooled


def precision_recall_intervals(counts, *, seed: int = 0, n_resamples: int = 2000,
                               confidence: float = 0.95):
    """95% intervals of pooled precision and recall by a two-level bootstrap.

    Parameters
    ----------
    counts : array of shape (K, 4)
        TP, FP, TN, FN of each of K repeats (each repeat a line-up of onions).

    Each resample draws K repeats with replacement, then for each drawn repeat the rates of its
    four outcomes from their Jeffreys posterior (Dirichlet of its counts + 1/2) and its onions
    from those rates (a multinomial of its line-up size), and pools the counts. The posterior
    step keeps an outcome never seen in a short line-up (no false positive among 29 calls)
    from counting as impossible.

    Returns
    -------
    ((precision_low, precision_high), (recall_low, recall_high))
        Percentile intervals; a resample with no positive call (or no blemished onion) has no
        precision (recall) and is left out of that interval.
    """
    import numpy as np

    counts = np.asarray(counts, dtype=np.int64)
    if counts.ndim != 2 or counts.shape[1] != 4 or len(counts) == 0:
        raise ValueError(f"counts must have shape (K, 4) with K >= 1; got {counts.shape}")
    rng = np.random.default_rng(seed)
    n = counts.sum(axis=1)
    pooled = np.zeros((n_resamples, 4), np.int64)
    for i in range(n_resamples):
        for k in rng.integers(0, len(counts), len(counts)):
            pooled[i] += rng.multinomial(n[k], rng.dirichlet(counts[k] + 0.5))
    tp, fp, fn = pooled[:, 0], pooled[:, 1], pooled[:, 3]
    alpha = 100 * (1 - confidence) / 2
    out = []
    for num, den in ((tp, tp + fp), (tp, tp + fn)):
        ok = den > 0
        values = num[ok] / den[ok]
        out.append((float(np.percentile(values, alpha)), float(np.percentile(values, 100 - alpha)))
                   if ok.any() else (float("nan"), float("nan")))
    return tuple(out)


def _ile(model: dict) -> dict[str, float]:
    """The learned reward's (or, for behaviour cloning, the cloned policy's) inverse learning
    error against the sorter's true reward: raw (``ile``) and in percent of the expert's value
    (``normalized_ile``)."""
    import numpy as np

    from irl.domains.onion_sorting import onion_sorting
    from irl.metrics import inverse_learning_error, normalized_inverse_learning_error

    domain = onion_sorting()
    if model["theta"] is None:  # behaviour cloning: its own policy, no reward
        learned = {"policy": np.asarray(model["policy_indices"], dtype=np.int64)}
    else:
        learned = {"learned_theta": np.array([model["theta"][name]
                                              for name in domain.task.feature_names])}
    return {"ile": float(inverse_learning_error(domain.mdp, domain.true_theta, **learned)),
            "normalized_ile": float(normalized_inverse_learning_error(
                domain.mdp, domain.true_theta, **learned))}
