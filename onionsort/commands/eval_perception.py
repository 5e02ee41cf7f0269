"""``onionsort eval-perception``: measure the perception models on a dataset.

Prints mAP of the detector (per view); the accuracy of each factor of the state classifier on
unoccluded steps, and the recall and precision of occluded steps (``--no-depth``: on colour
alone); and, per difficulty level, the inspection: how often the detector finds the onion, the
accuracy of each view alone, and the fused call on each onion (the Sawyer's views of it, the
sorter's views of it) for each fusion rule, with its precision, recall and expected calibration
error. ``--plots DIR`` draws the precision-recall curves.

Examples
--------
    onionsort eval-perception --data runs/heldout --split all
    onionsort eval-perception --data runs/fresh-paper --split all --views 4 --plots runs/pr
    onionsort eval-perception --data runs/heldout --split all --no-depth --json
"""

from __future__ import annotations

import json
from pathlib import Path

from onionsort.commands._args import add_device_argument, add_models_argument, subcommand


def register(subparsers) -> None:
    parser = subcommand(subparsers, "eval-perception", __doc__,
                        "measure the detector and the state classifier on a dataset")
    parser.add_argument("--data", type=Path, required=True, help="labelled dataset folder")
    parser.add_argument("--split", default="test",
                        help="split to evaluate on: train, val, test or all (test)")
    parser.add_argument("--no-depth", action="store_true", help="classifier on colour alone")
    parser.add_argument("--no-inspection", action="store_true",
                        help="without the inspection view")
    parser.add_argument("--views", type=int, default=None,
                        help="fuse the Sawyer's first VIEWS views of each onion (default: all "
                             "the dataset holds)")
    parser.add_argument("--plots", type=Path, default=None, metavar="DIR",
                        help="draw the inspection's precision-recall curves into DIR")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    add_models_argument(parser)
    add_device_argument(parser)
    parser.set_defaults(func=run)


def run(args) -> int:
    from onionsort.stages import PerceptionEvalConfig, eval_perception

    r = eval_perception(PerceptionEvalConfig(data=args.data, split=args.split,
                                             models=args.models, depth=not args.no_depth,
                                             inspection=not args.no_inspection,
                                             device=args.device, views=args.views,
                                             plots=args.plots))
    if args.json:
        print(json.dumps(r))
        return 0
    print(f"detector: mAP@0.5 {r['map50']:.3f}, mAP@0.5:0.95 {r['map50_95']:.3f}")
    for view, m in r["map_by_view"].items():
        if view != "all":
            print(f"  {view:10s} mAP@0.5 {m['map50']:.3f}, mAP@0.5:0.95 {m['map50_95']:.3f}")
    mode = "RGB-D" if r["depth"] else "colour only"
    print(f"state classifier ({mode}), unoccluded steps: " + ", ".join(
        f"{k} {v:.3f}" for k, v in r["accuracy"].items()))
    if r["prediction_after_first_inspection"] is not None:
        print(f"  prediction from each session's first inspection on: "
              f"{r['prediction_after_first_inspection']:.3f}")
    print(f"occluded steps: recall {r['occlusion_recall']:.3f}, precision "
          f"{r['occlusion_precision']:.3f} ({r['n_steps']} steps)")
    if "inspection_classifier" in r:
        _print_inspection(r["inspection_classifier"])
    for path in r.get("plots", []):
        print(f"wrote {path}")
    return 0


def _print_inspection(report: dict) -> None:
    def num(x) -> str:
        return "-" if x is None else f"{x:.3f}"

    robot = report["robot_rule"]
    rules = (f"the classifier's rule: {report['rule']}" if robot == report["rule"] else
             f"the sorter's classifier's rule: {report['rule']}, the robot's: {robot}")
    print(f"inspection (threshold {report['threshold']:.2f}, {rules}):")
    for level, sources in report["levels"].items():
        for source, m in sources.items():
            print(f"  {level:9s} {source:5s} {m['views']} views, onion found in "
                  f"{m['found']:.3f}; per view: rot call {num(m['rot_accuracy'])}, class call "
                  f"{num(m['view_accuracy'])}")
            for rule, f in m["fused"].items():
                print(f"      fused by {rule:8s}: accuracy {f['accuracy']:.3f}, precision "
                      f"{f['precision']:.3f}, recall {f['recall']:.3f}, ECE {f['ece']:.3f} "
                      f"({f['onions']} onions)")
