"""``onionsort eval-perception``: measure the detector and the state classifier on a dataset.

Prints mAP of the detector (per view), the accuracy of its good/blemished call on inspected
onions (the sorter's and the Sawyer's), the accuracy of each factor on unoccluded steps, and the
recall and precision of occluded steps; ``--no-depth`` measures the classifier on colour alone.

Examples
--------
    onionsort eval-perception --data runs/heldout --split all
    onionsort eval-perception --data runs/heldout --split all --no-depth --json
"""

from __future__ import annotations

import json
from pathlib import Path

from onionsort.commands._args import add_models_argument, subcommand


def register(subparsers) -> None:
    parser = subcommand(subparsers, "eval-perception", __doc__,
                        "measure the detector and the state classifier on a dataset")
    parser.add_argument("--data", type=Path, required=True, help="labelled dataset folder")
    parser.add_argument("--split", default="test",
                        help="split to evaluate on: train, val, test or all (test)")
    parser.add_argument("--no-depth", action="store_true", help="classifier on colour alone")
    parser.add_argument("--no-inspection", action="store_true",
                        help="without the inspection view")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    add_models_argument(parser)
    parser.set_defaults(func=run)


def run(args) -> int:
    from onionsort.stages import PerceptionEvalConfig, eval_perception

    r = eval_perception(PerceptionEvalConfig(data=args.data, split=args.split,
                                             models=args.models, depth=not args.no_depth,
                                             inspection=not args.no_inspection))
    if args.json:
        print(json.dumps(r))
        return 0
    print(f"detector: mAP@0.5 {r['map50']:.3f}, mAP@0.5:0.95 {r['map50_95']:.3f}")
    for view, m in r["map_by_view"].items():
        if view != "all":
            print(f"  {view:10s} mAP@0.5 {m['map50']:.3f}, mAP@0.5:0.95 {m['map50_95']:.3f}")
    for source, m in r["inspection_call"].items():
        print(f"  inspection call ({source}): accuracy {m['accuracy']:.3f} on {m['n']} onions, "
              f"{m['missed_blemished']} blemished missed, {m['false_blemished']} good called "
              "blemished")
    mode = "RGB-D" if r["depth"] else "colour only"
    print(f"state classifier ({mode}), unoccluded steps: " + ", ".join(
        f"{k} {v:.3f}" for k, v in r["accuracy"].items()))
    if r["prediction_after_first_inspection"] is not None:
        print(f"  prediction from each session's first inspection on: "
              f"{r['prediction_after_first_inspection']:.3f}")
    print(f"occluded steps: recall {r['occlusion_recall']:.3f}, precision "
          f"{r['occlusion_precision']:.3f} ({r['n_steps']} steps)")
    return 0
