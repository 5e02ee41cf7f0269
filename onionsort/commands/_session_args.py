"""Command-line options shared by the commands that simulate sorting sessions."""

from __future__ import annotations

import argparse


def add_session_arguments(parser: argparse.ArgumentParser, *, occlusion: float) -> None:
    """``--seed``, ``--occlusion``, ``--steps-per-session`` and ``--frames-per-step``."""
    parser.add_argument("--seed", type=int, default=0, help="root seed (0)")
    parser.add_argument("--occlusion", type=float, default=occlusion,
                        help=f"probability that a step is occluded by the passer-by ({occlusion})")
    parser.add_argument("--steps-per-session", type=int, default=20,
                        help="abstract sorting steps per session (20)")
    parser.add_argument("--frames-per-step", type=int, default=3,
                        help="frames rendered per step (3)")
