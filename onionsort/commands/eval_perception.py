"""``onionsort eval-perception``: measure the perception models on a dataset.

Prints mAP of the detector (per view, the Sawyer's views by its ``robot_detector.pt`` where the
folder has one; "any class" counts every box as one class: how well it finds the onions,
whatever it calls them); the accuracy of each factor of the state classifier on
unoccluded steps, and the recall and precision of occluded steps (``--no-depth``: on colour
alone); and, per difficulty level, the inspection: how often the detector finds the onion, the
accuracy of each view alone, and the fused call on each onion (the Sawyer's views of it, the
sorter's views of it) for each fusion rule, with its precision, recall and expected calibration
error; and how many sessions perception read backwards (more than half of their good/blemished
reads the other class). ``--plots DIR`` draws the precision-recall curves.

``--camera-shift SEEDS`` measures it all again through other cameras, once per seed (11 or
11,12,13): each session and each robot line-up through a camera of its own drawn from the seed
(white balance off by a colour temperature, another exposure and gamma, slight defocus, sensor
noise, JPEG; ``perception.camera_shift``), depth unchanged; ``--one-camera`` takes one camera
per seed for every session and line-up instead, as a lab with one camera would. It prints each
figure unchanged, through each seed's cameras, their mean, and the drops (how much worse than
unchanged: a fall, or for an ECE and the sessions read backwards a rise) of the mean and of the
worst seed. Use seeds that no training run or choice used.

Examples
--------
    onionsort eval-perception --data runs/heldout --split all
    onionsort eval-perception --data runs/fresh-paper --split all --views 4 --plots runs/pr
    onionsort eval-perception --data runs/heldout --split all --no-depth --json
    onionsort eval-perception --data runs/fresh-realistic --split all --views 5 \\
        --camera-shift 11,12,13
    onionsort eval-perception --data runs/fresh-realistic --split all --camera-shift 3737 \\
        --one-camera
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

    json: bool = option(False, after="one_camera", help="print one JSON object")


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
        _print_shift(r["camera_shift"])
    else:
        _print_figures(r)
    for path in r.get("plots", []):
        print(f"wrote {path}")
    return 0


def _print_figures(r: dict) -> None:
    """One ``eval_perception`` result, as measured (no camera shift)."""
    from onionsort.stages.calibrate import describe_session_swaps

    print(f"detector: mAP@0.5 {r['map50']:.3f}, mAP@0.5:0.95 {r['map50_95']:.3f}, "
          f"mAP@0.5 any class {r['map_by_view']['all']['map50_any_class']:.3f}")
    for view, m in r["map_by_view"].items():
        if view != "all":
            print(f"  {view:10s} mAP@0.5 {m['map50']:.3f}, mAP@0.5:0.95 {m['map50_95']:.3f}, "
                  f"mAP@0.5 any class {m['map50_any_class']:.3f}")
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


def _print_shift(shift: dict) -> None:
    """The figures through other cameras (:func:`onionsort.stages.calibrate.shift_summary`):
    unchanged, each seed's, their mean, and the drops of the mean and of the worst seed."""
    def num(x, width: int = 6, sign: str = "") -> str:
        if x is None:
            return f"{'-':>{width}s}"
        return f"{x:>{width}d}" if isinstance(x, int) else f"{x:>{sign}{width}.3f}"

    seeds = shift["seeds"]
    cameras = ("one camera for every session and robot line-up" if shift["one_camera"] else
               "each session and robot line-up a camera of its own")
    print(f"through other cameras (seed{'s' if len(seeds) > 1 else ''} "
          f"{', '.join(map(str, seeds))}): {cameras}; depth unchanged; a drop is how much "
          "worse than unchanged (for an ECE and the sessions read backwards, a rise)")
    figures = {(f"{name} (of {shift['sessions']})" if name == "sessions read backwards"
                else name): f for name, f in shift["figures"].items()}
    width = max(map(len, figures))
    columns = [f"{s:>6d}" for s in seeds] + ["  mean", "mean drop", "worst drop"]
    print(f"  {'figure':{width}s}  unchanged  " + "  ".join(
        f"{c:>6s}" if i < len(seeds) else c for i, c in enumerate(columns)))
    for name, f in figures.items():
        each = "  ".join(num(v) for v in f["changed"])
        print(f"  {name:{width}s}  {num(f['unchanged'], 9)}  {each}  {num(f['mean'])}  "
              f"{num(f['mean_drop'], 9, '+')}  {num(f['worst_drop'], 10, '+')}")
