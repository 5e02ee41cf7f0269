"""Stage ``demo``: the whole job on built-in defaults, into one run folder.

1. record 12 sessions of a person sorting onions (20 steps each; the passer-by occludes about 4
   of them) to MCAP, with a Rerun recording;
2. perceive them with the shipped detector and state classifier;
3. calibrate the observation model on freshly rendered held-out frames;
4. learn the sorter's reward with MMAP-BIRL, with MAP-BIRL (the same model reading the
   observations at face value: the ablation that shows what modelling observer noise is worth)
   and with HiddenDataEM;
5. let the Sawyer sort 50 onions (30 blemished) with each learned policy, inspection by the
   detector;
6. write ``results.json`` with the paper's Table 1 beside ours (:func:`table`).

``repeats`` runs steps 1, 2, 4 and 5 again with other seeds (repeat ``k`` uses seed
``seed + k``; one calibration serves all). ``results.json`` then holds the counts summed over
the repeats, each repeat's own, and 95% intervals of precision and recall from a two-level
bootstrap (repeats, then onions within a repeat), so both the spread between learned policies
and the finite line-up count. ``quick`` runs the pipeline small (4 sessions, 10 onions): the
end-to-end smoke test.

Example::

    from onionsort.stages import DemoConfig, demo
    results = demo(DemoConfig(out=Path("runs/demo-quick"), quick=True))
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path

from onionsort.stages.base import check_difficulty, check_output_folder, log_config, write_json
from onionsort.stages.calibrate import CalibrateConfig, calibrate
from onionsort.stages.dataset import DatasetConfig, make_dataset
from onionsort.stages.evaluate import EvaluateConfig, evaluate
from onionsort.stages.learn import LearnConfig, learn
from onionsort.stages.models import PerceptionModels
from onionsort.stages.perceive import PerceiveConfig, perceive
from onionsort.stages.record import RecordConfig, record

__all__ = ["METHODS", "PAPER_TABLE_1", "DemoConfig", "demo", "table"]

logger = logging.getLogger(__name__)

#: The paper's Table 1 (50 physical onions): TP, FP, TN, FN, precision, recall.
PAPER_TABLE_1 = {
    "mmap-birl": {"tp": 23, "fp": 2, "tn": 18, "fn": 7, "precision": 0.92, "recall": 0.767},
    "hidden-data-em": {"tp": 16, "fp": 10, "tn": 15, "fn": 9, "precision": 0.615,
                       "recall": 0.64},
}
METHODS = ("mmap-birl", "map-birl", "hidden-data-em")
#: The demo's line-up and recording sizes, full and quick.
SIZES = {False: {"sessions": 12, "steps": 20, "heldout": 1500, "onions": 50, "blemished": 30},
         True: {"sessions": 4, "steps": 12, "heldout": 360, "onions": 10, "blemished": 6}}


@dataclass(frozen=True)
class DemoConfig:
    """The demo's run folder, seed, size, repeats, perception difficulty and models.

    ``sessions`` None takes the size's default (12, quick 4). With ``repeats`` above 1 each
    repeat gets its own folder ``repeat_K``. ``difficulty`` names a level of
    :data:`robot.difficulty.DIFFICULTY_LEVELS`: the recorded sessions, the held-out frames the
    calibration is measured on, and the robot's inspection at evaluation all face it.
    """

    out: Path = Path("runs/demo")
    seed: int = 0
    quick: bool = False
    models: Path | None = None
    sessions: int | None = None
    repeats: int = 1
    difficulty: str = "clean"

    def __post_init__(self) -> None:
        if self.repeats < 1:
            raise ValueError(f"repeats must be >= 1; got {self.repeats}")
        if self.sessions is not None and self.sessions < 1:
            raise ValueError(f"sessions must be >= 1; got {self.sessions}")
        check_difficulty(self.difficulty)


def demo(config: DemoConfig) -> dict:
    """Run the whole job; write ``config.out/results.json`` and return its content."""
    import torch
    from tqdm import tqdm

    log_config("demo", config)
    torch.set_num_threads(2)
    start = time.perf_counter()
    out = config.out
    _check_new_folder(out)
    size = dict(SIZES[config.quick])
    if config.sessions is not None:
        size["sessions"] = config.sessions
    models = PerceptionModels.load(config.models)
    data = out / "heldout"
    make_dataset(DatasetConfig(out=data, frames=size["heldout"], seed=config.seed + 1000,
                               robot_onions=0, difficulty=config.difficulty))
    calibration, metrics = calibrate(CalibrateConfig(data=data, split="all",
                                                     out=out / "calibration",
                                                     models=config.models), models)
    logger.info("calibrated on %d held-out steps: state error rate %.3f, (state, action) "
                "error rate %.3f", metrics["n_steps"], calibration.state_error_rate,
                calibration.pair_error_rate)
    per_repeat: dict[str, list[dict]] = {m: [] for m in METHODS}
    with tqdm(total=config.repeats * (2 + len(METHODS)), desc="demo", unit="stage") as bar:
        for k in range(config.repeats):
            folder = out if config.repeats == 1 else out / f"repeat_{k}"
            seed = config.seed + k
            paths = record(RecordConfig(out=folder / "sessions", sessions=size["sessions"],
                                        steps_per_session=size["steps"], occlusion=0.2,
                                        seed=seed, rerun=folder / "sessions.rrd",
                                        difficulty=config.difficulty))
            bar.update()
            perceive(PerceiveConfig(sessions=tuple(paths), models=config.models), models)
            bar.update()
            for method in METHODS:
                per_repeat[method].append(_learn_and_sort(
                    method, paths, out / "calibration" / "calibration.json", folder / method,
                    seed, size, config, models))
                bar.update()
    results = {"methods": {m: _pooled(runs, config.seed) for m, runs in per_repeat.items()},
               "paper": PAPER_TABLE_1, "quick": config.quick, "seed": config.seed,
               "difficulty": config.difficulty, "repeats": config.repeats,
               "sessions": size["sessions"],
               "onions": size["onions"], "blemished": size["blemished"],
               "state_error_rate": calibration.state_error_rate,
               "pair_error_rate": calibration.pair_error_rate,
               "seconds": round(time.perf_counter() - start, 1)}
    write_json(out / "results.json", results)
    return results


def _check_new_folder(out: Path) -> None:
    """The demo writes a whole run folder: refuse one that holds anything (a finished demo, or
    one stopped half way), and make sure a new one can be written, before any work starts."""
    if out.is_dir():
        held = sorted(p.name for p in out.iterdir())
        if held:
            what = ("a demo (results.json)" if "results.json" in held
                    else "files of an earlier or interrupted run: " + ", ".join(held[:4])
                    + (", ..." if len(held) > 4 else ""))
            raise FileExistsError(f"--out {out} already holds {what}; choose a new --out "
                                  "(or remove the folder to run the demo there again)")
    check_output_folder(out)


def _learn_and_sort(method: str, sessions, calibration: Path, run_dir: Path, seed: int,
                    size: dict, config: DemoConfig, models: PerceptionModels) -> dict:
    """Learn with one method, let the Sawyer sort with its policy; one repeat's result."""
    t0 = time.perf_counter()
    model = learn(LearnConfig(sessions=tuple(sessions), calibration=calibration, out=run_dir,
                              method=method, seed=seed))
    learn_s = time.perf_counter() - t0
    result, _ = evaluate(EvaluateConfig(run=run_dir, onions=size["onions"],
                                        blemished=size["blemished"], seed=seed,
                                        models=config.models, difficulty=config.difficulty),
                         models)
    return {"seed": seed, "tp": result.tp, "fp": result.fp, "tn": result.tn, "fn": result.fn,
            "precision": result.precision, "recall": result.recall,
            "learn_seconds": round(learn_s, 3), "theta": model["theta"], "ile": _ile(model),
            "undecided": result.undecided}


def _pooled(runs: list[dict], seed: int) -> dict:
    """Counts summed over the repeats, precision and recall of the sums with their 95%
    intervals, the mean ILE, and every repeat's own result."""
    import numpy as np

    counts = np.array([[r["tp"], r["fp"], r["tn"], r["fn"]] for r in runs])
    tp, fp, tn, fn = (int(c) for c in counts.sum(axis=0))
    (p_lo, p_hi), (r_lo, r_hi) = precision_recall_intervals(counts, seed=seed)
    return {"tp": tp, "fp": fp, "tn": tn, "fn": fn,
            "precision": tp / (tp + fp) if tp + fp else 0.0,
            "recall": tp / (tp + fn) if tp + fn else 0.0,
            "precision_ci": [p_lo, p_hi], "recall_ci": [r_lo, r_hi],
            "ile": float(np.mean([r["ile"] for r in runs])), "per_repeat": runs}


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


def _ile(model: dict) -> float:
    """The learned reward's inverse learning error against the sorter's true reward."""
    import numpy as np

    from irl.domains.onion_sorting import onion_sorting
    from irl.metrics import inverse_learning_error

    domain = onion_sorting()
    theta = np.array([model["theta"][name] for name in domain.task.feature_names])
    return float(inverse_learning_error(domain.mdp, domain.true_theta, theta))


def table(results: dict) -> str:
    """The paper's Table 1 beside ours, as Markdown (ours with 95% intervals)."""
    rows = ["| method | source | TP | FP | TN | FN | precision | recall | ILE |",
            "|---|---|---|---|---|---|---|---|---|"]
    ours = f"ours (simulation, {results.get('repeats', 1)} repeat(s))"
    for method in METHODS:
        sources = [(ours, results["methods"][method])]
        if method in PAPER_TABLE_1:
            sources.insert(0, ("paper (physical robot)", PAPER_TABLE_1[method]))
        for source, r in sources:
            ile = f"{r['ile']:.3f}" if "ile" in r else "-"
            p, rc = f"{r['precision']:.3f}", f"{r['recall']:.3f}"
            if "precision_ci" in r:
                p += " [{:.2f}, {:.2f}]".format(*r["precision_ci"])
                rc += " [{:.2f}, {:.2f}]".format(*r["recall_ci"])
            rows.append(f"| {method} | {source} | {r['tp']} | {r['fp']} | {r['tn']} | "
                        f"{r['fn']} | {p} | {rc} | {ile} |")
    return "\n".join(rows)
