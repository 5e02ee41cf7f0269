"""``onionsort eval-perception``: measure the perception models on a dataset.

Prints mAP of the detector (per view); the accuracy of each factor of the state classifier on
unoccluded steps, and the recall and precision of occluded steps (``--no-depth``: on colour
alone); and, per difficulty level, the inspection: how often the detector finds the onion, the
accuracy of each view alone, and the fused call on each onion (the Sawyer's views of it, the
sorter's views of it) for each fusion rule, with its precision, recall and expected calibration
error; and how many sessions perception read backwards (more than half of their good/blemished
reads the other class). ``--plots DIR`` draws the precision-recall curves.

``--camera-shift SEED`` measures it all again through other cameras: each session and each
robot line-up through a camera of its own drawn from SEED (white balance off by a colour
temperature, another exposure and gamma, slight defocus, sensor noise, JPEG;
``perception.camera_shift``), depth unchanged, and prints each figure unchanged and changed,
with the drop. Use a seed that no training run used.

Examples
--------
    onionsort eval-perception --data runs/heldout --split all
    onionsort eval-perception --data runs/fresh-paper --split all --views 4 --plots runs/pr
    onionsort eval-perception --data runs/heldout --split all --no-depth --json
    onionsort eval-perception --data runs/fresh-realistic --split all --views 5 --camera-shift 2026
"""

from __future__ import annotations

import json
from dataclasses import dataclass

from onionsort.commands import add_command
from onionsort.configs import config_from_args, option
from onionsort.configs.calibrate import PerceptionEvalConfig


@dataclass(frozen=True)
class EvalPerceptionCommand(PerceptionEvalConfig):
    """The command's options: the stage's, and ``--json``."""

    json: bool = option(False, after="camera_shift", help="print one JSON object")


def register(subparsers) -> None:
    add_command(subparsers, "eval-perception", __doc__,
                "measure the detector and the state classifier on a dataset",
                EvalPerceptionCommand, run)


def run(args) -> int:
    from onionsort.stages import eval_perception

    r = eval_perception(config_from_args(PerceptionEvalConfig, args))
    if args.json:
        print(json.dumps(r))
        return 0
    if "camera_shift" in r:
        _print_shift(r, r["camera_shift"]["shifted"], r["camera_shift"]["seed"])
    else:
        _print_figures(r)
    for path in r.get("plots", []):
        print(f"wrote {path}")
    return 0


def _print_figures(r: dict) -> None:
    """One ``eval_perception`` result, as measured (no camera shift)."""
    from onionsort.stages.calibrate import describe_session_swaps

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
    print(describe_session_swaps(r["session_swaps"]))
    if "inspection_classifier" in r:
        _print_inspection(r["inspection_classifier"])


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
                      f"({f['onions']} onions; a calibrated model's by chance: median "
                      f"{f['ece_by_chance']:.3f}, 90th percentile "
                      f"{f['ece_by_chance_90']:.3f})")


def _print_shift(r: dict, shifted: dict, seed: int) -> None:
    def num(x) -> str:
        return "-" if x is None else f"{x:.3f}"

    from onionsort.stages.calibrate import perception_figures

    print(f"through other cameras (seed {seed}): each session and robot line-up a camera of "
          "its own; depth unchanged")
    before, after = perception_figures(r), perception_figures(shifted)
    width = max(map(len, before))
    print(f"  {'figure':{width}s}  unchanged  changed   drop")
    for name, value in before.items():
        other = after.get(name)
        drop = "-" if value is None or other is None else f"{value - other:+.3f}"
        print(f"  {name:{width}s}  {num(value):>9s}  {num(other):>7s}  {drop:>6s}")
    print(f"  {'sessions read backwards':{width}s}  "
          f"{r['session_swaps']['swapped']:>9d}  {shifted['session_swaps']['swapped']:>7d}  "
          f"(of {r['session_swaps']['sessions']})")
