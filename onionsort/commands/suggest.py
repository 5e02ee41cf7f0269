"""``onionsort suggest``: the states where another demonstration would help most.

Reads ``posterior.npz`` of a run learned with ``onionsort learn --posterior`` and lists the
states, in the task's words, ranked by the expected regret of the learned action there under
the posterior (the value of perfect information about the best action; see
:mod:`onionsort.stages.suggest`).

Examples
--------
    onionsort suggest runs/learn-mmap
    onionsort suggest runs/learn-mmap --top 10 --json
"""

from __future__ import annotations

import json
from dataclasses import dataclass

from onionsort.commands import add_command
from onionsort.configs import config_from_args, option
from onionsort.configs.suggest import SuggestConfig


@dataclass(frozen=True, kw_only=True)
class SuggestCommand(SuggestConfig):
    """The command's options: the stage's, and ``--json``."""

    json: bool = option(False, help="print the list as JSON")


def register(subparsers) -> None:
    add_command(subparsers, "suggest", __doc__,
                "the states where another demonstration would help the robot most",
                SuggestCommand, run)


def run(args) -> int:
    from onionsort.stages.suggest import suggest

    rows = suggest(config_from_args(SuggestConfig, args))
    if args.json:
        print(json.dumps(rows))
        return 0
    if not rows:
        print("every posterior sample agrees with the learned policy in every state: no "
              "demonstration is expected to change it")
        return 0
    print("where another demonstration would help most (expected regret of the learned "
          "action under the posterior, reward units):")
    for i, row in enumerate(rows, 1):
        print(f"{i:>2}. {row['description']} {row['name']}: learned {row['action']} "
              f"(confidence {row['confidence']:.2f}), expected regret "
              f"{row['expected_regret']:.3f}")
    return 0
