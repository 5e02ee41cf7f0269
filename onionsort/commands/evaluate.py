"""``onionsort evaluate``: the Sawyer executes a policy; count how well it sorts.

Loads the greedy policy of ``onionsort learn``'s run folder (or, with ``--policy expert``, the
task's own: perception measured apart from learning) and lets the Sawyer sort a line-up of
onions in PyBullet. At inspection it turns and tilts each onion before its camera
(``--inspection-views``, at most: it stops once no further view could change the call, which
under ``noisy-or`` is as soon as a view shows rot; ``--every-view`` takes them all); the
detector finds the onion in each view, the inspection classifier reads it, the views are
fused, and the onion is binned when the fused probability of a blemish reaches ``waste /
(waste + miss)`` (``--miss-cost``, ``--waste-cost``: by default the task's reward's, 0.5).
Reports TP (blemished in bin), FP (good in bin), TN (good left on the line), FN (blemished
left on the line), precision and recall, and writes ``evaluation.json``,
``evaluation.rrd`` (Rerun: the cameras, every inspection view, decisions, counts, and the work
cell and the Sawyer in 3D) and ``evaluation.mcap`` (the run as a session for Foxglove, ``rerun
mcap convert`` or ``recordings.open_session``: cameras, inspection views, ``/tf``,
``/joint_states``, ``/scene``, each step's decision and the running TP/FP/TN/FN) into RUN_DIR,
or ``--out DIR``.

With ``--ground-truth-inspection`` the robot knows each onion's class (learning measured apart
from perception); with ``--policy expert`` it sorts by the task's policy (perception measured
apart from learning): together they split any loss in two.

Precision and recall come with their 95% Wilson intervals, and each onion's fate, call and
probability go to ``tally.csv`` beside ``evaluation.json`` (``onionsort score`` counts it
against a truth CSV). ``--record-lineup DIR`` records the simulated line-up (every view of every
onion, ``lineups.csv``, ``truth.csv``); ``--lineup SOURCE --truth FILE.csv`` replays the policy
on a recorded line-up instead of the simulator (a lab's robot's views: docs/robot.md), each
inspected onion's views from the recording, its fate the policy's place decision; it writes
``evaluation.json`` and ``tally.csv``.

Examples
--------
    onionsort evaluate runs/learn-mmap --onions 50 --blemished 30 --seed 0
    onionsort evaluate --policy expert --onions 60 --blemished 30 --difficulty paper \\
        --out runs/eyes-paper
    onionsort evaluate runs/learn-mmap --ground-truth-inspection --json
    onionsort evaluate runs/learn-mmap --inspection-views 6 --miss-cost 3 --waste-cost 1
    onionsort evaluate runs/learn-mmap --no-rerun --no-mcap   # evaluation.json only
    onionsort evaluate runs/learn/mmap-birl runs/learn/map-birl   # in parallel, one line-up
    onionsort evaluate runs/learn-mmap --defer-below 0.9
        # (a RUN_DIR of `onionsort learn --posterior`) unsure states send the onion to a
        # check tray, counted apart (deferred, deferral_rate)
    onionsort evaluate --policy expert --seed 7 --record-lineup runs/lineup-7 --out runs/eyes
    onionsort evaluate runs/learn/mmap-birl runs/learn/map-birl --lineup runs/lineup-7 \\
        --truth runs/lineup-7/truth.csv
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

from onionsort.commands import add_command
from onionsort.configs import config_from_args, option
from onionsort.configs.evaluate import EvaluateConfig
from onionsort.configs.parallel import ParallelOptions


@dataclass(frozen=True, kw_only=True)
class EvaluateCommand(EvaluateConfig, ParallelOptions):
    """The command's options: the stage's for several runs at once, where they run, and
    ``--json``."""

    run: tuple[Path, ...] = option((), positional=True, nargs="*", metavar="RUN_DIR",
                                   help="folder(s) of `onionsort learn` (not with --policy "
                                        "expert); several are sorted in parallel, each on the "
                                        "same line-up, each writing into its own folder "
                                        "(default: none, with --policy expert)")
    json: bool = option(False, after="mcap", help="print the result as JSON")
    cli_help: ClassVar[dict[str, str]] = {"pieces": "runs"}


def register(subparsers) -> None:
    add_command(subparsers, "evaluate", __doc__,
                "the Sawyer sorts onions with a learned policy: precision and recall",
                EvaluateCommand, run)


def run(args) -> int:
    from onionsort.stages import evaluate
    from onionsort.stages.evaluate import evaluate_runs

    if args.policy == "expert" and args.run:
        raise ValueError(f"--policy expert sorts by the task's own policy; it takes no RUN_DIR "
                         f"(got {', '.join(map(str, args.run))}); give --out DIR")
    if len(args.run) > 1 and args.out is not None:
        raise ValueError("--out takes one run's outputs; several RUN_DIRs each write into "
                         "their own folder")
    configs = [config_from_args(EvaluateConfig, args, run=run) for run in (args.run or [None])]
    if len(configs) == 1:
        done = [evaluate(configs[0])]
    else:
        done = evaluate_runs(configs, config_from_args(ParallelOptions, args))
    for config, (result, out) in zip(configs, done, strict=True):
        _report(args, config, result, out)
    return 0


def _report(args, config, result, out: dict) -> None:
    if args.json:
        print(json.dumps({k: out[k] for k in ("method", "tp", "fp", "tn", "fn", "precision",
                                              "recall", "precision_ci", "recall_ci",
                                              "deferred", "deferral_rate")}))
        return
    how = ("ground truth" if args.ground_truth_inspection else
           f"{'' if config.every_view else 'up to '}{out['inspection_views']} views "
           f"({out['views_taken'] / max(sum(o['views'] > 0 for o in out['onions']), 1):.1f} "
           f"an onion) fused by {out['fusion']}, binned from P(blemished) >= "
           f"{out['threshold']:.2f}")
    n_bad = sum(o["blemished"] for o in out["onions"])
    where = (f"{args.difficulty} camera" if config.lineup is None else
             f"the recorded line-up {config.lineup}")
    print(f"{out['method']}: {out['n_onions']} onions ({n_bad} blemished), {where}, "
          f"inspection by {how}")
    print(result.table())
    written = ["evaluation.json", "tally.csv"]
    if config.lineup is None:
        written += [*(["evaluation.rrd"] if args.rerun else []),
                    *(["evaluation.mcap"] if args.mcap else [])]
    print(f"wrote {', '.join(str(config.folder / name) for name in written)}")
    if config.record_lineup is not None:
        print(f"recorded the line-up into {config.record_lineup} (its truth: "
              f"{config.record_lineup / 'truth.csv'})")
