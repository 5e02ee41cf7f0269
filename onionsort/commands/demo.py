"""``onionsort demo``: the whole job on built-in defaults, into one run folder.

1. record 12 sessions of a person sorting onions (20 steps each; the passer-by occludes about 4
   of them) to MCAP, with a Rerun recording;
2. perceive them with the shipped detector and state classifier;
3. calibrate the observation model on freshly rendered held-out frames;
4. learn the sorter's reward with MMAP-BIRL and with HiddenDataEM;
5. let the Sawyer sort 50 onions (30 blemished) with each learned policy, inspection by the
   detector;
6. print the paper's Table 1 beside ours and write ``results.json``.

``--quick`` runs the same pipeline small (4 sessions, 10 onions): the end-to-end smoke test.

Examples
--------
    onionsort demo
    onionsort demo --quick --out runs/demo-quick
"""

from __future__ import annotations

import argparse
import json
import logging
import time
from pathlib import Path

__all__ = ["PAPER_TABLE_1", "register"]

logger = logging.getLogger(__name__)

#: The paper's Table 1 (50 physical onions): TP, FP, TN, FN, precision, recall.
PAPER_TABLE_1 = {
    "mmap-birl": {"tp": 23, "fp": 2, "tn": 18, "fn": 7, "precision": 0.92, "recall": 0.767},
    "hidden-data-em": {"tp": 16, "fp": 10, "tn": 15, "fn": 9, "precision": 0.615,
                       "recall": 0.64},
}
METHODS = ("mmap-birl", "hidden-data-em")


def register(subparsers) -> None:
    """Add the ``demo`` subcommand."""
    parser = subparsers.add_parser(
        "demo", help="record, perceive, calibrate, learn and evaluate: the whole job",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=Path("runs/demo"), help="run folder")
    parser.add_argument("--quick", action="store_true", help="a small, fast run (smoke test)")
    parser.add_argument("--models", type=Path, default=None,
                        help="perception models folder (default: the shipped ones)")
    parser.set_defaults(func=run)


def _stage(name: str, argv: list[str]) -> None:
    from onionsort.cli import main

    logger.info("demo: %s", " ".join(["onionsort", *argv]))
    if main(argv) != 0:
        raise RuntimeError(f"the demo's {name} stage failed: onionsort {' '.join(argv)}")


def run(args: argparse.Namespace) -> int:
    import torch

    from onionsort.commands.evaluate import evaluate_run
    from onionsort.commands.learn import learn
    from onionsort.pipeline import PerceptionModels, evaluate_dataset, perceive_session
    from onionsort.plots import confusion_figure

    torch.set_num_threads(2)
    start = time.perf_counter()
    out = args.out
    if (out / "results.json").exists():
        raise FileExistsError(f"{out} already holds a demo (results.json); choose a new --out")
    sessions, steps, heldout = (4, 12, 360) if args.quick else (12, 20, 1500)
    onions, blemished = (10, 6) if args.quick else (50, 30)
    models = PerceptionModels.load(args.models)
    rec_dir = out / "sessions"
    _stage("record", ["record", "--sessions", str(sessions), "--steps-per-session", str(steps),
                      "--occlusion", "0.2", "--seed", str(args.seed), "--out", str(rec_dir),
                      "--rerun", str(out / "sessions.rrd")])
    paths = sorted(rec_dir.glob("*.mcap"))
    for path in paths:
        perceive_session(models, path)
    print(f"perceived {len(paths)} sessions")
    data = out / "heldout"
    _stage("dataset", ["dataset", "--frames", str(heldout), "--seed", str(args.seed + 1000),
                       "--robot-onions", "0", "--out", str(data)])
    calibration, metrics = evaluate_dataset(models, data, "all")
    cal_dir = out / "calibration"
    cal_dir.mkdir(parents=True, exist_ok=True)
    cal_path = calibration.save(cal_dir / "calibration.json", extra={
        "data": str(data), "split": "all", "models": models.describe(), "metrics": metrics})
    confusion_figure(calibration, cal_dir / "confusion.png")
    print(f"calibrated on {metrics['n_steps']} held-out steps: state error rate "
          f"{calibration.state_error_rate:.3f}, (state, action) error rate "
          f"{calibration.pair_error_rate:.3f}")
    results = {"methods": {}, "paper": PAPER_TABLE_1, "quick": args.quick, "seed": args.seed,
               "onions": onions, "blemished": blemished,
               "state_error_rate": calibration.state_error_rate,
               "pair_error_rate": calibration.pair_error_rate}
    for method in METHODS:
        run_dir = out / method
        t0 = time.perf_counter()
        model = learn(paths, method, cal_path, run_dir, seed=args.seed)
        learn_s = time.perf_counter() - t0
        result, _ = evaluate_run(run_dir, onions=onions, blemished=blemished, seed=args.seed,
                                 models=args.models)
        results["methods"][method] = {
            "tp": result.tp, "fp": result.fp, "tn": result.tn, "fn": result.fn,
            "precision": result.precision, "recall": result.recall,
            "learn_seconds": round(learn_s, 3), "theta": model["theta"],
            "ile": _ile(model), "undecided": result.undecided}
    results["seconds"] = round(time.perf_counter() - start, 1)
    tmp = out / "results.json.partial"
    tmp.write_text(json.dumps(results, indent=1))
    tmp.replace(out / "results.json")
    print(table(results))
    print(f"wrote {out / 'results.json'} ({results['seconds']:.0f} s)")
    return 0


def _ile(model: dict) -> float:
    """The learned reward's inverse learning error against the sorter's true reward."""
    import numpy as np

    from irl.domains.onion_sorting import onion_sorting
    from irl.metrics import inverse_learning_error

    domain = onion_sorting()
    theta = np.array([model["theta"][name] for name in domain.feature_names])
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
