"""``onionsort score``: TP/FP/TN/FN, precision and recall of a tally, against a truth CSV.

A tally gives each onion's fate: ``bin``, ``line`` (set back on the line) or ``tray`` (deferred
to a person); ``onionsort evaluate`` writes one (``tally.csv``), and a lab whose person counted
the bins by hand writes its own (columns ``lineup``, ``index``, ``fate``, ``call``,
``p_blemished``, ``deferred``; ``call`` and ``p_blemished`` may be empty). The truth CSV gives
each onion's class (``lineup``, ``index``, ``class``: ``good`` or ``blemished``). Prints the
confusion table, precision and recall with their 95% Wilson intervals, and the onions deferred
(counted apart); with ``--json``, one JSON object. The tally must be of exactly the onions the
truth names.

Examples
--------
    onionsort score runs/learn/mmap-birl/tally.csv --truth runs/lineup-7/truth.csv
    onionsort score lab/bins-counted.csv --truth lab/truth.csv --json
"""

from __future__ import annotations

import json
from dataclasses import dataclass

from onionsort.commands import add_command
from onionsort.configs import config_from_args, option
from onionsort.configs.score import ScoreConfig


@dataclass(frozen=True, kw_only=True)
class ScoreCommand(ScoreConfig):
    """The command's options: the stage's, and ``--json``."""

    json: bool = option(False, help="print tp, fp, tn, fn, precision, recall (with their "
                                    "intervals) and deferred as one JSON object")


def register(subparsers) -> None:
    add_command(subparsers, "score", __doc__,
                "precision and recall of a tally of fates against a truth CSV", ScoreCommand,
                run)


def run(args) -> int:
    from onionsort.stages.lineup import score

    counts = score(config_from_args(ScoreConfig, args))
    if args.json:
        doc = counts.to_dict()
        print(json.dumps({k: doc[k] for k in ("tp", "fp", "tn", "fn", "precision", "recall",
                                              "precision_ci", "recall_ci", "deferred",
                                              "deferral_rate")}))
        return 0
    print(f"{args.tally} against {args.truth}:")
    print(counts.table())
    return 0
