"""Stage ``demo``: the whole job on built-in defaults, into one run folder.

1. record 12 sessions of a person sorting onions (20 steps each; the passer-by occludes about 4
   of them) to MCAP, with a Rerun recording;
2. perceive them with the shipped detector and state classifier;
3. calibrate the observation model on freshly rendered held-out frames;
4. learn the sorter's reward with MMAP-BIRL and with HiddenDataEM;
5. let the Sawyer sort 50 onions (30 blemished) with each learned policy, inspection by the
   detector;
6. write ``results.json`` with the paper's Table 1 beside ours (:func:`table`).

``quick`` runs the same pipeline small (4 sessions, 10 onions): the end-to-end smoke test.

Example::

    from onionsort.stages import DemoConfig, demo
    results = demo(DemoConfig(out=Path("runs/demo-quick"), quick=True))
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path

from onionsort.stages.base import check_output_folder, log_config, write_json
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
METHODS = ("mmap-birl", "hidden-data-em")


@dataclass(frozen=True)
class DemoConfig:
    """The demo's run folder, seed, size and models."""

    out: Path = Path("runs/demo")
    seed: int = 0
    quick: bool = False
    models: Path | None = None


def demo(config: DemoConfig) -> dict:
    """Run the whole job; write ``config.out/results.json`` and return its content."""
    import torch

    log_config("demo", config)
    torch.set_num_threads(2)
    start = time.perf_counter()
    out = config.out
    if (out / "results.json").exists():
        raise FileExistsError(f"{out} already holds a demo (results.json); choose a new --out")
    check_output_folder(out)
    sessions, steps, heldout = (4, 12, 360) if config.quick else (12, 20, 1500)
    onions, blemished = (10, 6) if config.quick else (50, 30)
    models = PerceptionModels.load(config.models)
    paths = record(RecordConfig(out=out / "sessions", sessions=sessions,
                                steps_per_session=steps, occlusion=0.2, seed=config.seed,
                                rerun=out / "sessions.rrd"))
    perceive(PerceiveConfig(sessions=tuple(paths), models=config.models), models)
    data = out / "heldout"
    make_dataset(DatasetConfig(out=data, frames=heldout, seed=config.seed + 1000,
                               robot_onions=0))
    calibration, metrics = calibrate(CalibrateConfig(data=data, split="all",
                                                     out=out / "calibration",
                                                     models=config.models), models)
    logger.info("calibrated on %d held-out steps: state error rate %.3f, (state, action) "
                "error rate %.3f", metrics["n_steps"], calibration.state_error_rate,
                calibration.pair_error_rate)
    results = {"methods": {}, "paper": PAPER_TABLE_1, "quick": config.quick,
               "seed": config.seed, "onions": onions, "blemished": blemished,
               "state_error_rate": calibration.state_error_rate,
               "pair_error_rate": calibration.pair_error_rate}
    for method in METHODS:
        run_dir = out / method
        t0 = time.perf_counter()
        model = learn(LearnConfig(sessions=tuple(paths),
                                  calibration=out / "calibration" / "calibration.json",
                                  out=run_dir, method=method, seed=config.seed))
        learn_s = time.perf_counter() - t0
        result, _ = evaluate(EvaluateConfig(run=run_dir, onions=onions, blemished=blemished,
                                            seed=config.seed, models=config.models))
        results["methods"][method] = {
            "tp": result.tp, "fp": result.fp, "tn": result.tn, "fn": result.fn,
            "precision": result.precision, "recall": result.recall,
            "learn_seconds": round(learn_s, 3), "theta": model["theta"],
            "ile": _ile(model), "undecided": result.undecided}
    results["seconds"] = round(time.perf_counter() - start, 1)
    write_json(out / "results.json", results)
    return results


def _ile(model: dict) -> float:
    """The learned reward's inverse learning error against the sorter's true reward."""
    import numpy as np

    from irl.domains.onion_sorting import onion_sorting
    from irl.metrics import inverse_learning_error

    domain = onion_sorting()
    theta = np.array([model["theta"][name] for name in domain.task.feature_names])
    return float(inverse_learning_error(domain.mdp, domain.true_theta, theta))


def table(results: dict) -> str:
    """The paper's Table 1 beside ours, as Markdown."""
    rows = ["| method | source | TP | FP | TN | FN | precision | recall | ILE |",
            "|---|---|---|---|---|---|---|---|---|"]
    for method in METHODS:
        for source, r in (("paper (physical robot)", PAPER_TABLE_1[method]),
                          ("ours (simulation)", results["methods"][method])):
            ile = f"{r['ile']:.3f}" if "ile" in r else "-"
            rows.append(f"| {method} | {source} | {r['tp']} | {r['fp']} | {r['tn']} | "
                        f"{r['fn']} | {r['precision']:.3f} | {r['recall']:.3f} | {ile} |")
    return "\n".join(rows)
