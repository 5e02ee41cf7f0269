"""Compare two sets of perception models figure by figure, with a tolerance the sets resolve.

Reads results of ``onionsort eval-perception --json`` (one file per dataset, for the baseline
models and for the candidate, on the same datasets) and prints, for every figure that
``onionsort.stages.calibrate.perception_figures`` names, the baseline's and the candidate's
value (each the mean over the datasets given), the difference (positive: the candidate is
better; for an ECE, lower is better) and the tolerance: two binomial standard errors at the
figure's size, at least 0.02. The standard error is Agresti and Coull's, at the rate with two
hits and two misses added (``(x + 2) / (n + 4)``): at a rate of 1.000 the plain estimate is 0,
and a tolerance under one count of the figure is finer than its set resolves. A figure is
``worse`` when the candidate loses more than the tolerance. What a calibrated model's ECE
would be by chance is a reference, not a figure of the models, and is left out. Through other
cameras (``--camera-shift`` results) it prints the mean drops too.

The size of a figure (summed over the datasets):

- the detector's mAP and the state classifier's figures: the steps evaluated (``n_steps``);
- an inspection figure per view (onion found, rot call, class call): the views;
- a fused call: the onions for its accuracy and ECE, the onions it called blemished for its
  precision and the blemished onions for its recall (in a baseline written before
  ``eval-perception`` recorded those counts, the candidate's; where neither has them, the
  onions).

Usage::

    python scripts/compare_perception.py --base A1.json --base A2.json \
        --candidate B1.json --candidate B2.json [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from onionsort.stages.base import write_json
from onionsort.stages.calibrate import perception_figures, shift_summary


def fused_counts(f: dict) -> dict[str, int]:
    """A fused call's sizes: its onions, and for its precision and recall the onions it
    called blemished and the blemished ones (results written before ``eval-perception``
    recorded those two counts: its onions)."""
    n = f["onions"]
    return {"accuracy": n, "ECE": n, "precision": f.get("called_blemished", n),
            "recall": f.get("blemished", n)}


def figure_sizes(r: dict, other: dict | None = None) -> dict[str, int]:
    """Each figure's size (see the module's text) in one result; a fused call's counts that
    ``r`` lacks (written before they were recorded) are ``other``'s, the same call on the same
    onions by the other models, where it has them."""
    sizes = dict.fromkeys(perception_figures(r), r["n_steps"])
    levels = (other or {}).get("inspection_classifier", {}).get("levels", {})
    for level, sources in r.get("inspection_classifier", {}).get("levels", {}).items():
        for source, m in sources.items():
            who = f"inspection {level} {source}:"
            for name in sizes:
                if name.startswith(who):
                    sizes[name] = m["views"]
            for rule, f in m["fused"].items():
                g = levels.get(level, {}).get(source, {}).get("fused", {}).get(rule, {})
                if "blemished" not in f and g.get("onions") == f["onions"]:
                    f = {**f, **{k: g[k] for k in ("blemished", "called_blemished") if k in g}}
                for figure, n in fused_counts(f).items():
                    name = f"{who} fused by {rule}, {figure}"
                    if name in sizes:
                        sizes[name] = n
    return sizes


def tolerance(p: float, n: int) -> float:
    """Two binomial standard errors of a rate ``p`` of ``n``, at Agresti and Coull's rate
    (two hits and two misses added), at least 0.02."""
    if not n:
        return 0.02
    q = (min(max(p, 0.0), 1.0) * n + 2) / (n + 4)
    return max(0.02, 2 * math.sqrt(q * (1 - q) / n))


def load_result(path: Path) -> dict:
    """One result as ``eval-perception --json`` prints it. A file of unchanged figures and one
    result per camera seed (``{"unchanged": ..., "11": ..., "12": ...}``, each as
    ``onionsort.stages.calibrate._eval_figures`` returns it) is put in that shape."""
    r = json.loads(path.read_text())
    if "unchanged" not in r:
        return r
    out = dict(r["unchanged"])
    seeds = [k for k in r if k.isdigit()]
    if seeds:
        shifted = [r[k] for k in seeds]
        out["camera_shift"] = {"seeds": [int(k) for k in seeds],
                               "figures": shift_summary(out, shifted)}
    return out


def compare(base: list[dict], candidate: list[dict]) -> list[dict]:
    """One row per figure: the two means, the candidate's gain and the tolerance."""
    rows = []
    fb = [perception_figures(r) for r in base]
    fc = [perception_figures(r) for r in candidate]
    sizes = [figure_sizes(r, c) for r, c in zip(base, candidate, strict=True)]
    for name in fb[0]:
        a = [f.get(name) for f in fb]
        b = [f.get(name) for f in fc]
        if "by chance" in name or any(v is None for v in a + b):
            continue  # what chance gives is a reference, not the models' figure
        ma, mb = float(np.mean(a)), float(np.mean(b))
        n = sum(s[name] for s in sizes)
        higher_worse = "ECE" in name
        tol = tolerance(ma, n)
        gain = (ma - mb) if higher_worse else (mb - ma)
        rows.append({"figure": name, "base": ma, "candidate": mb, "gain": gain, "n": n,
                     "tolerance": tol, "verdict": ("worse" if gain < -tol else
                                                   "better" if gain > tol else "within")})
    return rows


def shift_rows(base: list[dict], candidate: list[dict]) -> list[dict]:
    """Through other cameras: each figure's mean drop (and the mean through the cameras) for
    both, averaged over the datasets that carry a ``camera_shift``."""
    def drops(rs):
        out = {}
        for r in rs:
            for name, f in r["camera_shift"]["figures"].items():
                out.setdefault(name, []).append((f["mean"], f["mean_drop"], f["worst_drop"]))
        return out
    db = drops([r for r in base if "camera_shift" in r])
    dc = drops([r for r in candidate if "camera_shift" in r])
    rows = []
    for name in db:
        values = db[name] + dc.get(name, [])
        if "by chance" in name or name not in dc or any(v is None for t in values for v in t):
            continue
        rows.append({"figure": name,
                     "base_mean": float(np.mean([t[0] for t in db[name]])),
                     "candidate_mean": float(np.mean([t[0] for t in dc[name]])),
                     "base_drop": float(np.mean([t[1] for t in db[name]])),
                     "candidate_drop": float(np.mean([t[1] for t in dc[name]])),
                     "base_worst_drop": float(max(t[2] for t in db[name])),
                     "candidate_worst_drop": float(max(t[2] for t in dc[name]))})
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", action="append", required=True, type=Path,
                        help="the baseline's eval-perception --json result (repeat)")
    parser.add_argument("--candidate", action="append", required=True, type=Path,
                        help="the candidate's result on the same dataset (repeat, same order)")
    parser.add_argument("--json", type=Path, help="also write the rows as JSON here")
    args = parser.parse_args(argv)
    if len(args.base) != len(args.candidate):
        print("error: give as many --candidate results as --base ones", file=sys.stderr)
        return 2
    base = [load_result(p) for p in args.base]
    cand = [load_result(p) for p in args.candidate]
    rows = compare(base, cand)
    print(f"{'figure':<62} {'base':>7} {'cand':>7} {'gain':>7} {'tol':>6}  verdict")
    for r in rows:
        print(f"{r['figure']:<62} {r['base']:7.3f} {r['candidate']:7.3f} {r['gain']:+7.3f} "
              f"{r['tolerance']:6.3f}  {r['verdict']}")
    worse = [r["figure"] for r in rows if r["verdict"] == "worse"]
    print(f"\nworse beyond tolerance: {len(worse)} of {len(rows)}" +
          (": " + "; ".join(worse) if worse else ""))
    shifted = shift_rows(base, cand)
    if shifted:
        print(f"\nthrough other cameras: {'figure':<50} {'base mean/drop':>16} "
              f"{'cand mean/drop':>16}")
        for r in shifted:
            print(f"  {r['figure']:<70} {r['base_mean']:.3f}/{r['base_drop']:+.3f}  "
                  f"{r['candidate_mean']:.3f}/{r['candidate_drop']:+.3f}")
    if args.json:
        write_json(args.json, {"unchanged": rows, "camera_shift": shifted})
    return 0


if __name__ == "__main__":
    sys.exit(main())
