"""``onionsort calibrate``: measure perception's confusion matrices -> the observation model.

Runs the detector and the state classifier on a held-out split of a labelled dataset and writes
``calibration.json`` (per-factor confusion counts, the models' hashes, the depth mode),
``observation_model.npz`` (``O[s, a, o]``) and ``confusion.png``. A calibration holds for the
sensor mode it measured, and ``learn`` refuses sessions of another: calibrate an imported
video with ``--no-depth`` (a video has no depth; import its inspection view with it,
``onionsort import --inspection``), and add ``--no-inspection`` only for a video without
one. Without the inspection view the onion's class is unobserved, and which class goes where
cannot be learned.

Examples
--------
    onionsort dataset --frames 1500 --seed 1 --out runs/heldout
    onionsort calibrate --data runs/heldout --split all --out runs/calibration
    onionsort calibrate --data runs/heldout --split all --no-depth --out runs/calibration-video
    onionsort calibrate --data runs/heldout --split all --no-depth --no-inspection \\
        --out runs/calibration-video-no-inspection
"""

from __future__ import annotations

from onionsort.commands import add_command
from onionsort.configs import config_from_args
from onionsort.configs.calibrate import CalibrateConfig


def register(subparsers) -> None:
    add_command(subparsers, "calibrate", __doc__,
                "measure perception's confusion matrices -> the observation model",
                CalibrateConfig, run)


def run(args) -> int:
    from onionsort.stages import calibrate
    from onionsort.stages.calibrate import describe_session_swaps

    calibration, metrics = calibrate(config_from_args(CalibrateConfig, args))
    mode = ("RGB-D" if args.depth else "colour only") + (
        "" if args.inspection else ", no inspection view")
    print(f"calibrated ({mode}) on {metrics['n_steps']} steps of {args.data} ({args.split}), "
          f"{calibration.n_observed} called unoccluded")
    for name, matrix in calibration.factors.items():
        print(f"  {name:13s} accuracy {matrix.accuracy:.3f}")
    print(f"effective noise: state error rate {calibration.state_error_rate:.3f}, "
          f"(state, action) error rate {calibration.pair_error_rate:.3f} "
          "(the paper estimated about 0.30 for its camera)")
    print(f"independence, as the observation model assumes it: state error rate "
          f"{calibration.independent_state_error_rate:.3f} from the factors' accuracies, "
          f"(state, action) {calibration.independent_pair_error_rate:.3f} from the state's and "
          "the action's")
    print(describe_session_swaps(metrics["session_swaps"]))
    print(f"wrote calibration.json, observation_model.npz and confusion.png to {args.out}")
    return 0
