"""Stage ``compare-perception``: a candidate's perception figures against a baseline's, figure by
figure, with a tolerance the datasets resolve.

Reads ``onionsort eval-perception --json`` results, one per dataset, of the baseline models and
of the candidate on the same datasets, in the same order. Each pair must be readings of one
dataset with the same options: the same dataset (its seed, frames and levels, where both
results record them), split, steps and inspection views (the onions fused may differ: those
each model found), and through other cameras both or
neither, with the same seeds. For every figure :func:`perception_figures` names it gives the
baseline's and the candidate's value, each the mean over the datasets; the candidate's gain
(positive: better; for an ECE, lower is better); and the tolerance: two standard errors of
that mean, at least 0.02. A set's standard error is binomial at the figure's size, at Agresti
and Coull's rate, with two hits and two misses added (``(x + 2) / (n + 4)``): at a rate of
1.000 the plain estimate is 0, and a tolerance under one count of the figure is finer than its
set resolves. Over sets of one size it is two standard errors at their summed size. A figure is
``worse`` when the candidate loses more than the tolerance, ``better`` when it gains more.
What a calibrated model's ECE would be by chance is a reference, not a figure of the models,
and is left out; a figure that some result lacks (a level another dataset does not hold) is
listed as not compared. Where both results were read through other cameras
(``eval-perception --camera-shift``), it gives each figure's mean and drops there too.

The size of a figure (summed over the datasets):

- the detector's mAP and the state classifier's figures: the steps evaluated (``n_steps``);
- an inspection figure per view (onion found, rot call, class call): the views;
- a fused call: the onions for its accuracy and ECE, the onions it called blemished for its
  precision and the blemished onions for its recall (in a result written before
  ``eval-perception`` recorded those counts, the other model's; where neither has them, the
  onions).

The tolerance covers the onions a set happens to hold, not what a second training run of the
same recipe changes, and each figure is judged on its own: with about 35 figures a difficulty
level, one of them may move beyond its tolerance by chance.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from onionsort.configs.calibrate import PerceptionCompareConfig
from onionsort.stages.calibrate import perception_figures, shift_summary, worse_when_higher

__all__ = ["PerceptionCompareConfig", "compare_figures", "compare_perception", "figure_sizes",
           "load_result", "mean_tolerance", "shift_rows", "tolerance"]


def tolerance(p: float, n: int) -> float:
    """Two binomial standard errors of a rate ``p`` of ``n``, at Agresti and Coull's rate
    (two hits and two misses added), at least 0.02."""
    return mean_tolerance(p, [n])


def mean_tolerance(p: float, sizes: list[int]) -> float:
    """Two standard errors of the mean of one rate ``p`` over sets of ``sizes`` (Agresti and
    Coull's rate at their summed size), at least 0.02: :func:`tolerance` at the summed size
    where the sets are of one size."""
    sizes = [n for n in sizes if n]
    if not sizes:
        return 0.02
    total = sum(sizes)
    q = (min(max(p, 0.0), 1.0) * total + 2) / (total + 4)
    return max(0.02, 2 * math.sqrt(q * (1 - q) * sum(1 / n for n in sizes)) / len(sizes))


def _fused_counts(f: dict) -> dict[str, int]:
    """A fused call's sizes: its onions, and for its precision and recall the onions it
    called blemished and the blemished ones (where the result lacks those: its onions)."""
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
                for figure, n in _fused_counts(f).items():
                    name = f"{who} fused by {rule}, {figure}"
                    if name in sizes:
                        sizes[name] = n
    return sizes


def load_result(path: Path | str) -> dict:
    """One result as ``eval-perception --json`` prints it; a ``ValueError`` naming ``path``
    where the file is not one. A file of unchanged figures and one result per camera seed
    (``{"unchanged": ..., "11": ..., "12": ...}``) is put in that shape."""
    path = Path(path)
    try:
        r = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"{path} is not JSON ({e}): give an `eval-perception --json` "
                         f"result") from None
    if isinstance(r, dict) and "unchanged" in r:
        seeds = [k for k in r if k.isdigit()]
        bad = next((k for k in ["unchanged", *seeds] if not isinstance(r[k], dict)), None)
        if bad is not None:
            raise ValueError(f"{path} is not an `eval-perception --json` result: its "
                             f"{bad!r} is not an object")
        out = dict(r["unchanged"])
        if seeds:
            try:
                figures = shift_summary(out, [r[k] for k in seeds])
            except (KeyError, TypeError) as e:
                raise ValueError(f"{path} is not an `eval-perception --json` result: a "
                                 f"camera seed's figures lack {e}") from None
            out["camera_shift"] = {"seeds": [int(k) for k in seeds], "figures": figures}
        r = out
    missing = [k for k in ("map_by_view", "accuracy", "n_steps")
               if not isinstance(r, dict) or k not in r]
    if missing:
        raise ValueError(f"{path} is not an `eval-perception --json` result: it lacks "
                         f"{', '.join(repr(k) for k in missing)}")
    return r


def _views(r: dict) -> dict[str, int]:
    """Per level and source (``"hard robot"``), the inspection's views: the dataset's, where
    the onions fused are those the models found, which two models may count apart."""
    return {f"{level} {source}": m.get("views")
            for level, sources in r.get("inspection_classifier", {}).get("levels", {}).items()
            for source, m in sources.items()}


def _identity(r: dict) -> dict | None:
    """The dataset a result read, as far as it records it: its seed, frames and levels (and
    its folder's name where it has no seed: a lab's own frames)."""
    data = r.get("data")
    if not isinstance(data, dict):
        return None
    keys = ("seed", "frames", "difficulty") + (("name",) if data.get("seed") is None else ())
    return {k: data.get(k) for k in keys}


def _check_pair(base: dict, cand: dict, base_path, cand_path) -> None:
    """Refuse two results that are not readings of one dataset with the same options."""
    both = f"{cand_path} and {base_path}"
    a, b = _identity(base), _identity(cand)
    if a is not None and b is not None and a != b:
        raise ValueError(f"{both} are readings of different datasets ({b} against {a}): give "
                         f"--candidate results in --base's order")
    if base.get("split") != cand.get("split"):
        raise ValueError(f"{both} read different splits ({cand.get('split')!r} against "
                         f"{base.get('split')!r})")
    if base["n_steps"] != cand["n_steps"]:
        raise ValueError(f"{both} are not readings of one dataset: they hold "
                         f"{cand['n_steps']} and {base['n_steps']} steps")
    has = ["inspection_classifier" in r for r in (cand, base)]
    if has[0] != has[1]:
        without, other = (cand_path, base_path) if not has[0] else (base_path, cand_path)
        raise ValueError(f"{without} was read without the inspection (`eval-perception "
                         f"--no-inspection`) and {other} with it: read both the same way")
    va, vb = _views(base), _views(cand)
    if va != vb:
        raise ValueError(f"{both} hold other inspection views per level "
                         f"({vb} against {va}): read both with the same `eval-perception --views`")
    shifted = ["camera_shift" in r for r in (cand, base)]
    if shifted[0] != shifted[1]:
        lone, other = (cand_path, base_path) if shifted[0] else (base_path, cand_path)
        raise ValueError(f"{lone} was read through other cameras (`eval-perception "
                         f"--camera-shift`) and {other} was not: read both the same way")
    if all(shifted):
        sa, sb = base["camera_shift"], cand["camera_shift"]
        if list(sa["seeds"]) != list(sb["seeds"]):
            raise ValueError(f"{both} went through other cameras of different seeds "
                             f"({sb['seeds']} against {sa['seeds']})")
        if sa.get("one_camera", False) != sb.get("one_camera", False):
            raise ValueError(f"{both} went through other cameras one with `eval-perception "
                             f"--one-camera` and the other without it")


def compare_figures(base: list[dict], candidate: list[dict]) -> tuple[list[dict], list[str]]:
    """One row per figure: ``figure``, the two means (``base``, ``candidate``), the
    candidate's ``gain``, the summed size ``n``, the ``tolerance`` (:func:`mean_tolerance`)
    and the ``verdict`` (``worse``, ``within`` or ``better``); and the figures not compared,
    which some result lacks or gives as None."""
    rows, skipped = [], []
    fb = [perception_figures(r) for r in base]
    fc = [perception_figures(r) for r in candidate]
    sizes = [figure_sizes(r, c) for r, c in zip(base, candidate, strict=True)]
    names = list(dict.fromkeys(name for f in fb + fc for name in f))
    for name in names:
        if "by chance" in name:
            continue  # what chance gives is a reference, not the models' figure
        a = [f.get(name) for f in fb]
        b = [f.get(name) for f in fc]
        if any(v is None for v in a + b):
            skipped.append(name)
            continue
        ma, mb = float(np.mean(a)), float(np.mean(b))
        n = [s[name] for s in sizes]
        tol = mean_tolerance(ma, n)
        gain = (ma - mb) if worse_when_higher(name) else (mb - ma)
        rows.append({"figure": name, "base": ma, "candidate": mb, "gain": gain, "n": sum(n),
                     "tolerance": tol, "verdict": ("worse" if gain < -tol else
                                                   "better" if gain > tol else "within")})
    return rows, skipped


def shift_rows(base: list[dict], candidate: list[dict]) -> list[dict]:
    """Through other cameras: each figure's mean through the cameras, its mean drop and its
    worst drop for both, over the datasets where both results carry a ``camera_shift``."""
    pairs = [(b, c) for b, c in zip(base, candidate, strict=True)
             if "camera_shift" in b and "camera_shift" in c]

    def drops(rs):
        out = {}
        for r in rs:
            for name, f in r["camera_shift"]["figures"].items():
                out.setdefault(name, []).append((f["mean"], f["mean_drop"], f["worst_drop"]))
        return out
    db, dc = drops([b for b, _ in pairs]), drops([c for _, c in pairs])
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


def compare_perception(config: PerceptionCompareConfig) -> dict:
    """The candidate's figures against the baseline's (see the module's text):
    ``{"datasets": n, "unchanged": rows, "worse": [figure, ...], "not_compared": [figure,
    ...], "camera_shift": rows}`` (:func:`compare_figures`, :func:`shift_rows`)."""
    base = [load_result(p) for p in config.base]
    cand = [load_result(p) for p in config.candidate]
    for b, c, pb, pc in zip(base, cand, config.base, config.candidate, strict=True):
        _check_pair(b, c, pb, pc)
    rows, skipped = compare_figures(base, cand)
    return {"datasets": len(base), "unchanged": rows,
            "worse": [r["figure"] for r in rows if r["verdict"] == "worse"],
            "not_compared": skipped,
            "camera_shift_datasets": sum("camera_shift" in r for r in base),
            "camera_shift": shift_rows(base, cand)}
