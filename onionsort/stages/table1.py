"""The paper's Table 1 and ours beside it: the demo writes it, the report shows it.

Both :mod:`onionsort.stages.demo` and :mod:`onionsort.stages.report` read it from here (the
report used to import it from the demo, which imports the report).
"""

from __future__ import annotations

#: The methods of the demo, in the order its table and the report list them.
from onionsort.configs.demo import METHODS as METHODS

__all__ = ["METHODS", "PAPER_TABLE_1", "table"]

#: The paper's Table 1 (50 physical onions): TP, FP, TN, FN, precision, recall.
PAPER_TABLE_1 = {
    "mmap-birl": {"tp": 23, "fp": 2, "tn": 18, "fn": 7, "precision": 0.92, "recall": 0.767},
    "hidden-data-em": {"tp": 16, "fp": 10, "tn": 15, "fn": 9, "precision": 0.615,
                       "recall": 0.64},
}


def table(results: dict) -> str:
    """The paper's Table 1 beside ours, as Markdown (ours with 95% intervals; with deferral,
    the same line-ups sorted deferring, precision and recall over the onions not deferred)."""
    rows = ["| method | source | TP | FP | TN | FN | precision | recall "
            "| ILE (% of the expert's value) |",
            "|---|---|---|---|---|---|---|---|---|"]
    ours = f"ours (simulation, {results.get('repeats', 1)} repeat(s))"
    for method in results["methods"]:
        sources = [(ours, results["methods"][method])]
        if method in results.get("deferring", {}):
            deferring = results["deferring"][method]
            sources.append((f"ours, deferring below {results['defer_below']:g} "
                            f"({deferring['deferred']} deferred, rate "
                            f"{deferring['deferral_rate']:.3f})", deferring))
        if method in PAPER_TABLE_1:
            sources.insert(0, ("paper (physical robot)", PAPER_TABLE_1[method]))
        for source, r in sources:
            ile = f"{r['ile']:.3f}" if "ile" in r else "-"
            if "normalized_ile" in r:
                ile += f" ({r['normalized_ile']:.1f}%)"
            p, rc = f"{r['precision']:.3f}", f"{r['recall']:.3f}"
            if "precision_ci" in r:
                p += " [{:.2f}, {:.2f}]".format(*r["precision_ci"])
                rc += " [{:.2f}, {:.2f}]".format(*r["recall_ci"])
            rows.append(f"| {method} | {source} | {r['tp']} | {r['fp']} | {r['tn']} | "
                        f"{r['fn']} | {p} | {rc} | {ile} |")
    return "\n".join(rows)
