"""``onionsort evaluate``: the Sawyer executes a learned policy; count how well it sorts.

Loads the greedy policy of a learning run (``RUN_DIR/model.json`` from ``onionsort learn``) and
lets the Sawyer sort a line-up of onions in PyBullet: every abstract action is a real motion
(IK, suction grasp), and the onion's class at inspection comes from the detector on the
inspection view, so perception errors count. Reports TP (blemished in bin), FP (good in bin),
TN (good left on the line), FN (blemished left on the line), precision and recall, as a table
and in ``RUN_DIR/evaluation.json``, with a Rerun recording of the sort
(``RUN_DIR/evaluation.rrd``).

Examples
--------
    onionsort evaluate runs/learn-mmap --onions 50 --blemished 30 --seed 0
    onionsort evaluate runs/learn-mmap --ground-truth-inspection --json
"""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path

__all__ = ["evaluate_run", "load_policy", "register"]

logger = logging.getLogger(__name__)


def register(subparsers) -> None:
    """Add the ``evaluate`` subcommand."""
    parser = subparsers.add_parser(
        "evaluate", help="the Sawyer sorts onions with a learned policy: precision and recall",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run", type=Path, metavar="RUN_DIR", help="folder of `onionsort learn`")
    parser.add_argument("--onions", type=int, default=50, help="onions on the line (50)")
    parser.add_argument("--blemished", type=int, default=30, help="how many are blemished (30)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--models", type=Path, default=None,
                        help="perception models folder (default: the shipped ones)")
    parser.add_argument("--ground-truth-inspection", action="store_true",
                        help="perfect inspection instead of the detector (for comparison)")
    parser.add_argument("--no-rerun", action="store_true", help="skip the Rerun recording")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.set_defaults(func=run)


def load_policy(run_dir: Path):
    """The greedy policy ``actions[s]`` (48,) of a learning run, with clear errors."""
    import numpy as np

    from irl.domains.onion_sorting import N_ACTIONS, N_STATES

    path = Path(run_dir) / "model.json"
    if not path.is_file():
        raise FileNotFoundError(f"{run_dir} holds no learned model (no model.json); run "
                                "`onionsort learn ... --out RUN_DIR` first")
    try:
        doc = json.loads(path.read_text())
        actions = np.asarray(doc["policy_indices"], dtype=np.int64)
    except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{path} is not a learned model ({exc})") from None
    if actions.shape != (N_STATES,) or actions.min() < 0 or actions.max() >= N_ACTIONS:
        raise ValueError(f"{path}: the policy must give one action in [0, {N_ACTIONS}) for each "
                         f"of the {N_STATES} onion-sorting states; got shape {actions.shape}")
    return actions, doc


def inspection_classifier(detector):
    """``classify(rgb) -> Prediction`` from the detector's best box in the inspection view."""
    from irl.domains.onion_sorting import Prediction
    from state_abstraction.perceive import inspected_class

    def classify(rgb):
        cls = inspected_class(detector.detect([rgb])[0])
        return Prediction.UNKNOWN if cls is None else Prediction(
            Prediction.BAD if cls == 1 else Prediction.GOOD)

    return classify


def evaluate_run(run_dir: Path, *, onions: int = 50, blemished: int = 30, seed: int = 0,
                 models: Path | None = None, ground_truth: bool = False,
                 rerun: bool = True):
    """Evaluate a run's policy; writes ``evaluation.json`` (and ``.rrd``); returns the result."""
    from robot.evaluation import evaluate_policy

    actions, doc = load_policy(run_dir)
    detector = None
    if ground_truth:
        classify = "ground-truth"
    else:
        from onionsort.pipeline import PerceptionModels

        detector = PerceptionModels.load(models).detector
        classify = inspection_classifier(detector)
    on_step, rec = None, None
    if rerun:
        import rerun as rr

        from recordings.rerun_eval import evaluation_blueprint, log_evaluation_step

        rec = rr.RecordingStream("onionsort_evaluate")
        rec.save(Path(run_dir) / "evaluation.rrd", default_blueprint=evaluation_blueprint())
        rec.log("evaluation/inspection", rr.AnnotationContext(
            [(0, "good", (40, 200, 60)), (1, "blemished", (230, 40, 40))]), static=True)

        def on_step(event):
            log_evaluation_step(rec, event)
            if detector is not None and event.inspection is not None:
                det = detector.detect([event.inspection])[0]  # the boxes behind the decision
                rec.log("evaluation/inspection/detections", rr.Boxes2D(
                    array=det.boxes, array_format=rr.Box2DFormat.XYXY, class_ids=det.classes,
                    labels=[f"{s:.2f}" for s in det.scores]))

    result = evaluate_policy(actions, n_onions=onions, n_blemished=blemished, seed=seed,
                             classify=classify, render=rerun, on_step=on_step)
    if rec is not None:
        rec.flush()
        rec.disconnect()
    out = {"method": doc.get("method"), "seed": seed, "inspection":
           "ground truth" if ground_truth else "detector", **result.to_dict()}
    tmp = Path(run_dir) / "evaluation.json.partial"
    tmp.write_text(json.dumps(out, indent=1))
    tmp.replace(Path(run_dir) / "evaluation.json")
    return result, out


def run(args: argparse.Namespace) -> int:
    import torch

    torch.set_num_threads(2)
    result, out = evaluate_run(args.run, onions=args.onions, blemished=args.blemished,
                               seed=args.seed, models=args.models,
                               ground_truth=args.ground_truth_inspection,
                               rerun=not args.no_rerun)
    if args.json:
        print(json.dumps({k: out[k] for k in ("method", "tp", "fp", "tn", "fn", "precision",
                                              "recall")}))
    else:
        print(f"{out['method']}: {args.onions} onions ({args.blemished} blemished), "
              f"inspection by the {out['inspection']}")
        print(result.table())
        print(f"wrote {args.run / 'evaluation.json'}")
    return 0
