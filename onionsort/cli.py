"""The ``onionsort`` console script.

Examples
--------
    onionsort experiment forestworld --quick --out runs/forestworld-quick
    onionsort experiment sorting --occlusion 0,0.1,0.2 --noise 0.3 --batches 5 --out runs/sorting
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

from onionsort import __version__
from onionsort.commands import COMMAND_MODULES


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="onionsort",
        description="Learn to sort onions from occluded, noisy demonstrations (MMAP-BIRL).",
    )
    parser.add_argument("--version", action="version", version=f"onionsort {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more logging")
    parser.add_argument("--debug", action="store_true",
                        help="show the traceback of an error instead of a one-line message")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=[logging.WARNING, logging.INFO, logging.DEBUG][min(args.verbose, 2)],
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    try:
        return int(args.func(args) or 0)
    except (ValueError, OSError) as exc:  # bad input or an unusable path: one line, exit 2
        if args.debug:
            raise
        print(f"onionsort {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"onionsort {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
