"""``onionsort compare-perception``: are a candidate's perception models better or worse than a
baseline's, beyond what the datasets resolve?

Reads ``onionsort eval-perception --json`` results, one per dataset: ``--base`` those of the
baseline models (the shipped ones, say), ``--candidate`` those of the candidate (a lab's
fine-tuned models, say) on the same datasets in the same order. Prints every figure: the
baseline's and the candidate's value, each the mean over the datasets, the candidate's gain
(for an ECE, lower is better), the tolerance, and the verdict: ``worse`` or ``better`` where
the gain passes the tolerance, two binomial standard errors at the figure's size (steps,
views or onions, summed over the datasets), at least 0.02. Then the figures worse beyond the
tolerance, and, where both were read through other cameras (``eval-perception --camera-shift``,
the same seeds), each figure's mean there and its drop. With ``--json``, one JSON object. Two
results that are not readings of one dataset read the same way (another dataset, split or
``eval-perception --views``; through other cameras one and not the other) are
refused.

The tolerance covers the onions a set happens to hold, not what a second training run would
change; with about 35 figures a difficulty level, one may pass its tolerance by chance, so
read a loss on one figure beside the rest, and on more datasets before acting on it.

Examples
--------
    onionsort eval-perception --data runs/lab-heldout --split all --json > runs/base.json
    onionsort eval-perception --data runs/lab-heldout --split all --models runs/lab-models \\
        --json > runs/lab.json
    onionsort compare-perception --base runs/base.json --candidate runs/lab.json
    onionsort compare-perception --base runs/a-base.json --base runs/b-base.json \\
        --candidate runs/a-lab.json --candidate runs/b-lab.json --json
"""

from __future__ import annotations

import json
from dataclasses import dataclass

from onionsort.commands import add_command
from onionsort.configs import config_from_args, option
from onionsort.configs.calibrate import PerceptionCompareConfig


@dataclass(frozen=True, kw_only=True)
class ComparePerceptionCommand(PerceptionCompareConfig):
    """The command's options: the stage's, and ``--json``."""

    json: bool = option(False, help="print the rows, the figures worse and those through "
                                    "other cameras as one JSON object")


def register(subparsers) -> None:
    add_command(subparsers, "compare-perception", __doc__,
                "a candidate's perception figures against a baseline's, with a tolerance",
                ComparePerceptionCommand, run)


def run(args) -> int:
    from onionsort.stages.compare_perception import compare_perception

    r = compare_perception(config_from_args(PerceptionCompareConfig, args))
    if args.json:
        print(json.dumps(r))
    else:
        print_comparison(r)
    return 0


def print_comparison(r: dict) -> None:
    """:func:`~onionsort.stages.compare_perception.compare_perception`'s result as a table."""
    rows = r["unchanged"]
    width = max([len(x["figure"]) for x in rows] + [6])
    print(f"over {r['datasets']} dataset(s): the mean of each")
    print(f"{'figure':<{width}} {'base':>7} {'cand':>7} {'gain':>7} {'tol':>6}  verdict")
    for x in rows:
        print(f"{x['figure']:<{width}} {x['base']:7.3f} {x['candidate']:7.3f} "
              f"{x['gain']:+7.3f} {x['tolerance']:6.3f}  {x['verdict']}")
    worse = r["worse"]
    print(f"\nworse beyond the tolerance: {len(worse)} of {len(rows)}"
          + (": " + "; ".join(worse) if worse else ""))
    if r["not_compared"]:
        print(f"not compared, lacking in some result: {'; '.join(r['not_compared'])}")
    if r["camera_shift"]:
        width = max(len(x["figure"]) for x in r["camera_shift"])
        print(f"\nthrough other cameras, over {r['camera_shift_datasets']} dataset(s): the mean "
              f"through the cameras / its drop\n{'figure':<{width}} {'base':>14} {'cand':>14}")
        for x in r["camera_shift"]:
            print(f"{x['figure']:<{width}} {x['base_mean']:7.3f}/{x['base_drop']:+.3f} "
                  f"{x['candidate_mean']:7.3f}/{x['candidate_drop']:+.3f}")
