"""Command-line options that several commands share."""

from __future__ import annotations

import argparse
from pathlib import Path

from onionsort.configs.export import EXPORT_FORMATS as EXPORT_FORMATS
from onionsort.configs.export import ROS2_STORAGES as ROS2_STORAGES


def add_session_arguments(parser: argparse.ArgumentParser, *, occlusion: float) -> None:
    """``--seed``, ``--occlusion``, ``--steps-per-session`` and ``--frames-per-step``."""
    parser.add_argument("--seed", type=int, default=0, help="root seed (0)")
    parser.add_argument("--occlusion", type=float, default=occlusion,
                        help=f"probability that a step is occluded by the passer-by ({occlusion})")
    parser.add_argument("--steps-per-session", type=int, default=20,
                        help="abstract sorting steps per session (20)")
    parser.add_argument("--frames-per-step", type=int, default=3,
                        help="frames rendered per step (3)")


def add_models_argument(parser: argparse.ArgumentParser) -> None:
    """``--models``: the perception models folder."""
    parser.add_argument("--models", type=Path, default=None,
                        help="folder with detector.pt, state_classifier.pt and "
                             "inspection_classifier.pt, and optionally "
                             "robot_inspection_classifier.pt for the Sawyer's inspection "
                             "(default: the models shipped with onionsort)")


def add_connect_argument(parser: argparse.ArgumentParser, *,
                         what: str = "its Rerun recordings") -> None:
    """``--connect URL``: also stream the command's Rerun recordings to a viewer over gRPC."""
    parser.add_argument("--connect", metavar="URL",
                        help=f"also stream {what} to the Rerun viewer at URL, e.g. on another "
                             "machine (rerun+http://HOST:9876/proxy; start it there with "
                             "`rerun`)")


#: :data:`perception.fusion.FUSION_RULES`, repeated so that building the parser does not import
#: torch (a test checks they agree)
FUSION_RULES = ("noisy-or", "log-odds")
#: :data:`onionsort.stages.inspection.INSPECTION_CAMERAS`, repeated for the same reason
INSPECTION_CAMERAS = ("both", "robot")
#: The choices below are repeated too, so that building the parser (every command does, at
#: start) imports neither ``irl`` (and scipy) nor every stage: :data:`onionsort.stages.base.
#: DEVICES`, :data:`irl.inference.BACKENDS` and :data:`irl.experiments.METHODS`
#: (the export's choices come from its config, :mod:`onionsort.configs.export`)
DEVICES = ("auto", "cpu", "cuda")
BACKENDS = ("numpy", "numba")
METHODS = ("mmap-birl", "map-birl", "hidden-data-em", "maxent", "bc", "bc-em")
#: The four reward learners of the paper: what ``experiment`` runs by default
IRL_METHODS = METHODS[:4]
#: :data:`onionsort.stages.label.LABEL_FORMATS`, repeated for the same reason
LABEL_FORMATS = ("coco", "yolo")
#: :data:`onionsort.stages.label.IMPORT_FORMATS`, repeated for the same reason
IMPORT_FORMATS = ("coco", "yolo", "labelstudio")
#: :data:`onionsort.stages.label_select.SELECT_FORMATS`, repeated for the same reason
SELECT_FORMATS = ("coco", "labelstudio")


def add_device_argument(parser: argparse.ArgumentParser) -> None:
    """``--device {auto,cpu,cuda}``: where torch runs the perception models."""
    parser.add_argument("--device", choices=DEVICES, default="auto",
                        help="where torch runs: auto (CUDA when present, else the CPU; "
                             "default), cpu or cuda")


def add_inspection_arguments(parser: argparse.ArgumentParser) -> None:
    """``--inspection-views``, ``--miss-cost``, ``--waste-cost`` and ``--fusion``: how the
    Sawyer inspects an onion and decides."""
    from robot.inspection_poses import INSPECTION_VIEWS

    parser.add_argument("--inspection-views", type=int, default=INSPECTION_VIEWS,
                        help="views the Sawyer takes of every onion, turning and tilting it "
                             f"({INSPECTION_VIEWS})")
    parser.add_argument("--miss-cost", type=float, default=None,
                        help="cost of a blemished onion left on the line (default: from the "
                             "task's reward, 8)")
    parser.add_argument("--waste-cost", type=float, default=None,
                        help="cost of a good onion in the bin (default: from the task's "
                             "reward, 8); the robot bins an onion when P(blemished) >= "
                             "waste / (waste + miss)")
    parser.add_argument("--fusion", choices=FUSION_RULES, default=None,
                        help="how the views are fused (default: the inspection classifier's "
                             "own rule)")


def add_backend_argument(parser: argparse.ArgumentParser) -> None:
    """``--backend {numpy,numba}``: the forward-backward kernels of the learners that run it."""
    parser.add_argument("--backend", choices=BACKENDS, default="numpy",
                        help="forward-backward kernels: numpy (default) or numba, compiled "
                             "and equal to rounding (pip install -e \".[fast]\"); used by "
                             "mmap-birl and bc-em; the other learners ignore it")


def add_posterior_method_argument(parser: argparse.ArgumentParser) -> None:
    """``--posterior-method {mcmc,laplace}``: how the posterior over rewards is sampled."""
    parser.add_argument("--posterior-method", choices=("mcmc", "laplace"), default="mcmc",
                        help="HMC chains on the exact gradient (mcmc), or a Gaussian at the MAP "
                             "(laplace, fast)")


def add_session_swaps_argument(parser: argparse.ArgumentParser) -> None:
    """``--session-swaps``: MMAP-BIRL doubts how each whole session was read."""
    parser.add_argument("--session-swaps", action="store_true",
                        help="mmap-birl: let a whole session's reads of the onion's class have "
                             "been backwards, at the rate the calibration measured on its "
                             "held-out sessions; its posterior weighs the reading of the "
                             "sessions the MAP implies, its complement, and every reading one "
                             "session from either")


def add_defer_argument(parser: argparse.ArgumentParser, *, needs: str) -> None:
    """``--defer-below P``: the robot defers where it is less sure than P of its action."""
    parser.add_argument("--defer-below", type=float, default=None, metavar="P",
                        help="defer to a person where the robot is less sure than P that its "
                             "next action is right: the learned policy's confidence in it "
                             f"({needs}), weighed over what an inspected onion may be by the "
                             "inspection's P(blemished); the onion goes to a check tray, "
                             "counted apart")


def subcommand(subparsers, name: str, doc: str, help_: str) -> argparse.ArgumentParser:
    """A subparser whose description is the command module's docstring."""
    return subparsers.add_parser(name, help=help_, description=doc,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)


def methods_list(choices):
    """An option's type: one learner or several, comma-separated, each of ``choices``."""
    def parse(text: str) -> tuple[str, ...]:
        names = tuple(t.strip() for t in text.split(","))
        for name in names:
            if name not in choices:
                raise argparse.ArgumentTypeError(
                    f"invalid choice: {name!r} (choose from {', '.join(choices)})")
        return names

    return parse


def floats(text: str) -> tuple[float, ...]:
    """A comma-separated list of numbers, for argparse ``type=``."""
    try:
        return tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError:
        msg = f"expected comma-separated numbers; got {text!r}"
        raise argparse.ArgumentTypeError(msg) from None


def add_parallel_arguments(parser: argparse.ArgumentParser, *, pieces: str) -> None:
    """``--executor``, ``--workers`` and ``--ray-address``: where a stage's independent
    ``pieces`` run (:class:`onionsort.stages.parallel.ParallelOptions`)."""
    group = parser.add_argument_group("parallel")
    group.add_argument("--executor", choices=["local", "ray"], default="local",
                       help=f"run the {pieces} on local worker processes (default) or as Ray "
                            "tasks (pip install -e \".[ray]\")")
    group.add_argument("--workers", type=int, metavar="N",
                       help=f"{pieces} at a time: local worker processes, or the CPUs of a new "
                            "local Ray instance (default: one per core, or one per two cores "
                            "where a piece runs on torch's threads, as in perceive and "
                            "calibrate; 1: one after another in this process)")
    group.add_argument("--ray-address", metavar="ADDRESS",
                       help="the Ray cluster to join, e.g. auto or ray://head:10001 (default: "
                            "$RAY_ADDRESS, else a local Ray instance of --workers CPUs)")


def parallel_options(args: argparse.Namespace) -> dict:
    """The :class:`~onionsort.stages.parallel.ParallelOptions` fields of parsed arguments."""
    return {"executor": args.executor, "workers": args.workers,
            "ray_address": args.ray_address}
