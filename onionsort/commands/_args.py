"""Command-line options that several commands share."""

from __future__ import annotations

import argparse
from pathlib import Path


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
                        help="folder with state_classifier.pt and detector.pt (default: the "
                             "models shipped with onionsort)")


def add_connect_argument(parser: argparse.ArgumentParser, *,
                         what: str = "its Rerun recordings") -> None:
    """``--connect URL``: also stream the command's Rerun recordings to a viewer over gRPC."""
    parser.add_argument("--connect", metavar="URL",
                        help=f"also stream {what} to the Rerun viewer at URL, e.g. on another "
                             "machine (rerun+http://HOST:9876/proxy; start it there with "
                             "`rerun`)")


def add_backend_argument(parser: argparse.ArgumentParser) -> None:
    """``--backend {numpy,numba}``: the forward-backward kernels of the learners that run it."""
    from irl.inference import BACKENDS

    parser.add_argument("--backend", choices=BACKENDS, default="numpy",
                        help="forward-backward kernels: numpy (default) or numba, compiled "
                             "and equal to rounding (pip install -e \".[fast]\"); used by "
                             "mmap-birl; the other learners ignore it")


def subcommand(subparsers, name: str, doc: str, help_: str) -> argparse.ArgumentParser:
    """A subparser whose description is the command module's docstring."""
    return subparsers.add_parser(name, help=help_, description=doc,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)


def floats(text: str) -> tuple[float, ...]:
    """A comma-separated list of numbers, for argparse ``type=``."""
    try:
        return tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError:
        msg = f"expected comma-separated numbers; got {text!r}"
        raise argparse.ArgumentTypeError(msg) from None
