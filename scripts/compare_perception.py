"""Compare two sets of perception models figure by figure: ``onionsort compare-perception``
under the name the notes of docs/notes/ ran it by, with their ``--json OUT`` (write the rows
to OUT) kept.

Usage::

    python scripts/compare_perception.py --base A1.json --base A2.json \
        --candidate B1.json --candidate B2.json [--json OUT]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from onionsort.cli import describe_error, is_bad_input
from onionsort.commands.compare_perception import print_comparison
from onionsort.stages.base import write_json
from onionsort.stages.compare_perception import PerceptionCompareConfig, compare_perception


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", action="append", required=True, type=Path,
                        help="the baseline's eval-perception --json result (repeat)")
    parser.add_argument("--candidate", action="append", required=True, type=Path,
                        help="the candidate's result on the same dataset (repeat, same order)")
    parser.add_argument("--json", type=Path, help="also write the rows as JSON here")
    args = parser.parse_args(argv)
    try:
        r = compare_perception(PerceptionCompareConfig(base=args.base,
                                                       candidate=args.candidate))
    except Exception as e:
        if not is_bad_input(e):
            raise
        print(f"error: {describe_error(e)}", file=sys.stderr)
        return 2
    print_comparison(r)
    if args.json:
        write_json(args.json, r)
    return 0


if __name__ == "__main__":
    sys.exit(main())
