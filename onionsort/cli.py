"""The ``onionsort`` console script.

Every error a user can cause (a bad value, a path that cannot be read or written, a file that
is not what it should be) ends the command with one line on stderr that names what is wrong,
what was given and what to do, and exit code 2; ``--debug`` shows the traceback instead. An
unexpected failure (a bug) is also one line, with exit code 1 and a pointer to ``--debug``.

Examples
--------
    onionsort experiment forestworld --quick --out runs/forestworld-quick
    onionsort experiment sorting --occlusion 0,0.1,0.2 --noise 0.3 --batches 5 --out runs/sorting
"""

from __future__ import annotations

import argparse
import errno
import importlib
import logging
import sys

from onionsort import __version__
from onionsort.commands import COMMAND_MODULES

__all__ = ["DESCRIPTION", "OneLineParser", "build_parser", "describe_error", "is_bad_input",
           "main"]

#: What to do about an ``OSError`` without a message of its own, by its ``errno``.
_OS_HINTS = {
    errno.ENOENT: "check the path",
    errno.ENOTDIR: "a part of the path is a file, not a folder; choose another path",
    errno.EISDIR: "it is a folder; give a file",
    errno.EEXIST: "choose another name, or remove it",
    errno.EACCES: "choose a path you may read and write, or change its permissions",
    errno.EPERM: "choose a path you may read and write, or change its permissions",
    errno.EROFS: "the file system is read-only; choose another path",
    errno.ENOSPC: "the disk is full; free some space or choose another disk",
    errno.ENAMETOOLONG: "choose a shorter path",
}


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line: what is wrong and where the usage
    is (instead of argparse's usage block followed by the error)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message}; see `{self.prog} --help`\n")


#: What ``onionsort --help`` says before the commands.
DESCRIPTION = """Learn to sort onions from occluded, noisy demonstrations (MMAP-BIRL).

Each command is a stage of the pipeline (record, perceive, calibrate, learn, evaluate) or runs
them all (demo); each command's `--help` says what it does, what it writes, and its options.
An error a user can cause is one line and exit code 2 (`--debug` shows the traceback).

Examples
--------
    onionsort demo --quick --out runs/demo-quick
    onionsort demo
    onionsort -v learn runs/rec/*.mcap --observation-model runs/cal/calibration.json \\
        --out runs/learn
"""


def build_parser() -> argparse.ArgumentParser:
    """The parser of every command (each module of
    :data:`~onionsort.commands.COMMAND_MODULES` adds its own)."""
    parser = OneLineParser(prog="onionsort", description=DESCRIPTION,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"onionsort {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0,
                        help="more logging: -v for progress (INFO), -vv for debugging (DEBUG)")
    parser.add_argument("--debug", action="store_true",
                        help="show the traceback of an error instead of a one-line message")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(subparsers)
    return parser


def is_bad_input(exc: BaseException) -> bool:
    """Whether ``exc`` says the input was bad (exit code 2) rather than that onionsort failed.

    Bad input: an unusable path or file (``OSError``), a value or a file's content refused by
    validation (``ValueError``, which ``json.JSONDecodeError`` and the recordings' own errors
    are, ``TypeError``, ``KeyError``), and a file the MCAP library cannot decode.
    """
    if isinstance(exc, OSError | ValueError | TypeError | KeyError):
        return True
    return any(cls.__module__.split(".")[0] == "mcap" for cls in type(exc).__mro__)


def describe_error(exc: BaseException) -> str:
    """``exc`` as one line: its own message where it has one, else what it says about which
    path or key, with what to do."""
    if isinstance(exc, OSError) and exc.strerror:
        where = exc.filename if exc.filename is not None else "a path"
        text = f"{where}: {exc.strerror}"
        if exc.filename2 is not None:
            text += f" (and {exc.filename2})"
        hint = _OS_HINTS.get(exc.errno)
        text += f"; {hint}" if hint else ""
    elif isinstance(exc, KeyError):
        text = (f"a record lacks the key {exc.args[0]!r} (KeyError): the file is not one "
                "this version of onionsort wrote; run with --debug for the traceback"
                if exc.args else "KeyError; run with --debug for the traceback")
    else:
        text = str(exc).strip() or f"{type(exc).__name__} (no message)"
        if not isinstance(exc, OSError | ValueError | TypeError) and type(exc).__name__ not in text:
            text = f"{type(exc).__name__}: {text}"
    return " ".join(line.strip() for line in text.splitlines() if line.strip())


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=[logging.WARNING, logging.INFO, logging.DEBUG][min(args.verbose, 2)],
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    prog = f"onionsort {args.command}"
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:
        if args.debug:
            raise
        if is_bad_input(exc):  # bad input or an unusable path: one line, exit 2
            print(f"{prog}: error: {describe_error(exc)}", file=sys.stderr)
            return 2
        if type(exc).__name__ == "WorkerLost":  # a killed worker: neither input nor a bug
            print(f"{prog}: error: {' '.join(str(exc).split())}", file=sys.stderr)
            return 1
        print(f"{prog}: internal error: {describe_error(exc)} (run again with --debug for "
              "the traceback, and please report it)", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
