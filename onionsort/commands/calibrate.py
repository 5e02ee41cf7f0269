"""``onionsort calibrate``: measure perception's confusion matrices -> the observation model.

Runs the detector and the state classifier on a held-out split of a labelled dataset and writes
``calibration.json`` (per-factor confusion counts, the models' hashes, the depth mode),
``observation_model.npz`` (``O[s, a, o]``) and ``confusion.png``. A calibration holds for the
sensor mode it measured: calibrate with ``--no-depth --no-inspection`` for imported videos.

Examples
--------
    onionsort dataset --frames 1500 --seed 1 --out runs/heldout
    onionsort calibrate --data runs/heldout --split all --out runs/calibration
    onionsort calibrate --data runs/heldout --split all --no-depth --no-inspection \\
        --out runs/calibration-video
"""

from __future__ import annotations

from pathlib import Path

from onionsort.commands._args import (
    add_device_argument,
    add_models_argument,
    add_parallel_arguments,
    parallel_options,
    subcommand,
)


def register(subparsers) -> None:
    parser = subcommand(subparsers, "calibrate", __doc__,
                        "measure perception's confusion matrices -> the observation model")
    parser.add_argument("--data", type=Path, required=True, help="labelled dataset folder")
    parser.add_argument("--split", default="test",
                        help="the held-out split to use: train, val, test or all (test)")
    parser.add_argument("--out", type=Path, required=True, help="folder for the calibration")
    parser.add_argument("--smoothing", type=float, default=1.0,
                        help="additive smoothing of the confusion counts (1.0)")
    parser.add_argument("--no-depth", action="store_true",
                        help="measure the classifier on colour alone (for sessions without depth)")
    parser.add_argument("--no-inspection", action="store_true",
                        help="measure without the inspection view (imported videos have none)")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace a calibration.json already in --out")
    add_models_argument(parser)
    add_device_argument(parser)
    add_parallel_arguments(parser, pieces="dataset's sessions")
    parser.set_defaults(func=run)


def run(args) -> int:
    from onionsort.stages import CalibrateConfig, calibrate
    from onionsort.stages.calibrate import describe_session_swaps

    calibration, metrics = calibrate(CalibrateConfig(
        data=args.data, out=args.out, split=args.split, smoothing=args.smoothing,
        models=args.models, depth=not args.no_depth, inspection=not args.no_inspection,
        overwrite=args.overwrite, device=args.device, **parallel_options(args)))
    mode = ("colour only" if args.no_depth else "RGB-D") + (
        ", no inspection view" if args.no_inspection else "")
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
