"""``onionsort evaluate``: the Sawyer executes a learned policy; count how well it sorts.

Loads the greedy policy of ``onionsort learn``'s run folder and lets the Sawyer sort a line-up
of onions in PyBullet, inspection by the detector. Reports TP (blemished in bin), FP (good in
bin), TN (good left on the line), FN (blemished left on the line), precision and recall, and
writes ``RUN_DIR/evaluation.json``, ``RUN_DIR/evaluation.rrd`` (Rerun: the cameras, decisions,
counts, and the work cell and the Sawyer in 3D) and ``RUN_DIR/evaluation.mcap`` (the run as a
session for Foxglove, ``rerun mcap convert`` or ``recordings.open_session``: cameras, inspection
views, ``/tf``, ``/joint_states``, ``/scene``, each step's decision and the running
TP/FP/TN/FN).

Examples
--------
    onionsort evaluate runs/learn-mmap --onions 50 --blemished 30 --seed 0
    onionsort evaluate runs/learn-mmap --ground-truth-inspection --json
    onionsort evaluate runs/learn-mmap --no-rerun --no-mcap   # evaluation.json only
"""

from __future__ import annotations

import json
from pathlib import Path

from onionsort.commands._args import add_connect_argument, add_models_argument, subcommand


def register(subparsers) -> None:
    parser = subcommand(subparsers, "evaluate", __doc__,
                        "the Sawyer sorts onions with a learned policy: precision and recall")
    parser.add_argument("run", type=Path, metavar="RUN_DIR", help="folder of `onionsort learn`")
    parser.add_argument("--onions", type=int, default=50, help="onions on the line (50)")
    parser.add_argument("--blemished", type=int, default=30, help="how many are blemished (30)")
    parser.add_argument("--seed", type=int, default=0)
    add_models_argument(parser)
    parser.add_argument("--ground-truth-inspection", action="store_true",
                        help="perfect inspection instead of the detector (for comparison)")
    parser.add_argument("--no-rerun", action="store_true", help="skip the Rerun recording")
    parser.add_argument("--no-mcap", action="store_true",
                        help="skip the session MCAP of the run (evaluation.mcap)")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    add_connect_argument(parser, what="the Sawyer's run (evaluation.rrd)")
    from robot.difficulty import DIFFICULTY_LEVELS

    parser.add_argument("--difficulty", choices=list(DIFFICULTY_LEVELS), default="clean",
                        help="perception difficulty of the world (clean)")
    parser.set_defaults(func=run)


def run(args) -> int:
    from onionsort.stages import EvaluateConfig, evaluate

    result, out = evaluate(EvaluateConfig(
        run=args.run, onions=args.onions, blemished=args.blemished, seed=args.seed,
        models=args.models, ground_truth_inspection=args.ground_truth_inspection,
        rerun=not args.no_rerun, difficulty=args.difficulty, mcap=not args.no_mcap,
        connect=args.connect))
    if args.json:
        print(json.dumps({k: out[k] for k in ("method", "tp", "fp", "tn", "fn", "precision",
                                              "recall")}))
        return 0
    print(f"{out['method']}: {args.onions} onions ({args.blemished} blemished), "
          f"inspection by the {out['inspection']}")
    print(result.table())
    written = ["evaluation.json", *(["evaluation.rrd"] if not args.no_rerun else []),
               *(["evaluation.mcap"] if not args.no_mcap else [])]
    print(f"wrote {', '.join(str(args.run / name) for name in written)}")
    return 0
