"""Figures (matplotlib, written as PNG): experiment sweeps, confusion matrices, learning curves."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

COLORS = {"mmap-birl": "C0", "map-birl": "C1", "hidden-data-em": "C3", "maxent": "C2",
          "bc": "C7", "bc-em": "C4"}
MARKERS = {"mmap-birl": "o", "map-birl": "s", "hidden-data-em": "^", "maxent": "D", "bc": "x",
           "bc-em": "v"}

#: What a summary row (``irl.experiments.summarize``) holds per plotted quantity: the key of the
#: mean, the prefix of its bootstrap interval, the axis label and the y scale.
METRICS = {
    "ile": ("ile_mean", "ile_ci", "ILE", ("symlog", 0.01)),
    # a batch's normalized ILE is 0 or tens of percent (a wrong action on a path): linear
    "normalized_ile": ("normalized_ile_mean", "normalized_ile_ci", "normalized ILE (%)",
                       ("linear", None)),
    "exact_policy": ("exact_policy_rate", "exact_policy_ci", "exact-policy rate",
                     ("linear", (-0.03, 1.03))),
    "seconds": ("seconds_mean", "seconds_ci", "fit time (s)", ("symlog", 0.01)),
}


def _rows(points, **fixed):
    return [p for p in points if all(p[k] == v for k, v in fixed.items())]


def _methods(points):
    return list(dict.fromkeys(p["method"] for p in points))


def _setting_label(p, keys) -> str:
    names = {"occlusion": "occl.", "noise": "noise", "trajectories": "demos",
             "length": "length", "learner": "learner beta"}
    parts = []
    for k in keys:
        v = p[k]
        if k in ("occlusion", "noise"):
            parts.append(f"{names[k]} {v:.0%}")
        elif k == "learner":
            parts.append(f"{names[k]} {v} ({p['learner_beta']:.3g})")
        else:
            parts.append(f"{names[k]} {v}")
    return ", ".join(parts)


def _varying(points, keys) -> list[str]:
    return [k for k in keys if len({p[k] for p in points}) > 1]


def _set_yscale(ax, yscale) -> None:
    kind, arg = yscale
    if kind == "symlog":  # values span orders of magnitude between methods; 0 stays readable
        ax.set_yscale("symlog", linthresh=arg)
        ax.set_ylim(bottom=0)
    elif arg is not None:
        ax.set_ylim(*arg)
    else:
        ax.set_ylim(bottom=0)


def _panel(ax, points, x_key, metric, *, x_scale=100.0, dodge=1.0):
    """One line per method (mean over batches) with its 95% bootstrap band. ``dodge`` > 1
    shifts the methods' markers apart multiplicatively (for a log x axis) so equal means stay
    visible."""
    mean_key, ci, ylabel, yscale = METRICS[metric]
    methods = _methods(points)
    for m, method in enumerate(methods):
        rows = sorted(_rows(points, method=method), key=lambda p: p[x_key])
        if not rows:
            continue
        xs = np.array([p[x_key] for p in rows], float) * x_scale
        xs = xs * dodge ** (m - (len(methods) - 1) / 2)
        color = COLORS.get(method)
        ax.plot(xs, [p[mean_key] for p in rows], "-", marker=MARKERS.get(method, "o"),
                color=color, label=method, ms=4)
        ax.fill_between(xs, [p[f"{ci}_low"] for p in rows], [p[f"{ci}_high"] for p in rows],
                        color=color, alpha=0.12, lw=0)
    _set_yscale(ax, yscale)
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)


def _grid(points, row_keys, col_key, draw, title, path, plt):
    """A figure with one row per combination of ``row_keys`` and one column per value of
    ``col_key`` (one column if None); ``draw(ax, rows)`` fills each panel."""
    row_combos = list(dict.fromkeys(tuple(p[k] for k in row_keys) for p in points))
    cols = [None] if col_key is None else sorted({p[col_key] for p in points})
    fig, axes = plt.subplots(len(row_combos), len(cols), squeeze=False,
                             figsize=(4.6 * len(cols), 3.4 * len(row_combos)))
    for i, combo in enumerate(row_combos):
        for j, col in enumerate(cols):
            fixed = dict(zip(row_keys, combo, strict=True))
            if col_key is not None:
                fixed[col_key] = col
            sub = _rows(points, **fixed)
            ax = axes[i][j]
            draw(ax, sub)
            label = _setting_label(sub[0], list(fixed)) if sub else ""
            ax.set_title(f"{title}: {label}" if title and label else title or label,
                         fontsize=9)
            if i == 0 and j == 0:
                ax.legend(fontsize=7)
    return _save_captioned(fig, points, path, plt)


def _save_captioned(fig, points, path: Path, plt) -> Path:
    """Save with a caption line on top saying what the lines and intervals are."""
    n = sorted({p["batches"] for p in points})
    batches = f"{n[0]}" if len(n) == 1 else f"{n[0]}-{n[-1]}"
    fig.suptitle(f"mean over {batches} batches; 95% percentile-bootstrap interval over batches",
                 fontsize=8, color="0.35", y=1 - 0.06 / fig.get_figheight(), va="top")
    return _save(fig, path, plt)


def plot_sweep(results: Sequence, out: Path, *, title: str = "",
               points: Sequence[dict] | None = None) -> list[Path]:
    """The sweep's figures; lines are means over batches, bands their 95% bootstrap intervals.

    - ``ile_vs_occlusion.png``, ``seconds_vs_occlusion.png``: per noise level (columns);
    - ``ile_vs_noise.png``: without occlusion, when several noise levels were swept;
    - ``normalized_ile_vs_demonstrations.png``, ``exact_policy_vs_demonstrations.png``,
      ``seconds_vs_demonstrations.png``: against the number of demonstrations (log2 axis), per
      noise level, when several numbers were swept;
    - ``vs_learner_beta.png``: normalized ILE and exact-policy rate per learner setting, when
      several were swept.

    Other swept settings (length, learner beta, ...) get one row of panels each. ``points`` are
    the rows of ``irl.experiments.summarize(results)`` (computed with seed 0 if not given).
    Returns the files written.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if points is None:
        from irl.experiments import summarize

        points = summarize(results)
    points = list(points)
    written = []

    occluded = [p for p in points if p["occlusion"] > 0]
    other = _varying(occluded, ("trajectories", "length", "learner"))
    if occluded and (len({p["occlusion"] for p in occluded}) > 1 or not other):
        for metric, what, name in (("ile", "", "ile_vs_occlusion.png"),
                                   ("seconds", "run time", "seconds_vs_occlusion.png")):
            def draw(ax, sub, metric=metric):
                _panel(ax, sub, "occlusion", metric)
                ax.set_xlabel("occlusion (%)")
            written.append(_grid(occluded, other, "noise", draw, f"{title} {what}".strip(),
                                 out / name, plt))
    clear = [p for p in points if p["occlusion"] == 0]
    if len({p["noise"] for p in clear}) > 1:
        keys = _varying(clear, ("trajectories", "length", "learner"))

        def draw_noise(ax, sub):
            _panel(ax, sub, "noise", "ile")
            ax.set_xlabel("observation noise (%)")
        label = f"{title}: no occlusion" if title else "no occlusion"
        written.append(_grid(clear, keys, None, draw_noise, label, out / "ile_vs_noise.png",
                             plt))

    if len({p["trajectories"] for p in points}) > 1:
        keys = _varying(points, ("occlusion", "length", "learner"))
        for metric in ("normalized_ile", "exact_policy", "seconds"):
            def draw_demos(ax, sub, metric=metric):
                _panel(ax, sub, "trajectories", metric, x_scale=1.0, dodge=1.04)
                ticks = sorted({p["trajectories"] for p in sub})
                ax.set_xscale("log", base=2)
                ax.set_xticks(ticks, [str(t) for t in ticks])
                ax.set_xlabel("demonstrations per batch")
            written.append(_grid(points, keys, "noise", draw_demos, title,
                                 out / f"{metric}_vs_demonstrations.png", plt))

    if len({p["learner"] for p in points}) > 1:
        written.append(_learner_figure(points, title, out / "vs_learner_beta.png", plt))
    return written


def _learner_figure(points, title, path, plt):
    """Normalized ILE (top) and exact-policy rate (bottom) per learner setting, with 95%
    bootstrap error bars; one column per other setting."""
    keys = _varying(points, ("occlusion", "noise", "trajectories", "length")) or ["noise"]
    combos = list(dict.fromkeys(tuple(p[k] for k in keys) for p in points))
    settings = sorted({(p["learner_beta"], p["learner"]) for p in points})
    labels = [f"{lab}\nβ={beta:.3g}" for beta, lab in settings]
    methods = _methods(points)
    fig, axes = plt.subplots(2, len(combos), squeeze=False, sharex=True,
                             figsize=(max(4.6, 1.1 * len(settings) + 1.5) * len(combos), 6.4))
    for j, combo in enumerate(combos):
        sub = _rows(points, **dict(zip(keys, combo, strict=True)))
        for i, metric in enumerate(("normalized_ile", "exact_policy")):
            mean_key, ci, ylabel, yscale = METRICS[metric]
            ax = axes[i][j]
            for m, method in enumerate(methods):
                xs, ys, lo, hi = [], [], [], []
                for x, (_, lab) in enumerate(settings):
                    rows = _rows(sub, method=method, learner=lab)
                    if rows:
                        xs.append(x + (m - (len(methods) - 1) / 2) * 0.12)
                        ys.append(rows[0][mean_key])
                        lo.append(rows[0][mean_key] - rows[0][f"{ci}_low"])
                        hi.append(rows[0][f"{ci}_high"] - rows[0][mean_key])
                ax.errorbar(xs, ys, yerr=[lo, hi], fmt=MARKERS.get(method, "o"),
                            color=COLORS.get(method), label=method, capsize=3, ms=4)
            _set_yscale(ax, yscale)
            ax.set_ylabel(ylabel)
            ax.grid(alpha=0.3)
            ax.set_xticks(range(len(settings)), labels, fontsize=8)
            if i == 0:
                label = _setting_label(sub[0], keys)
                ax.set_title(f"{title}: {label}" if title else label, fontsize=9)
            else:
                ax.set_xlabel("learner setting (data from the true beta)")
        if j == 0:
            axes[0][0].legend(fontsize=7)
    return _save_captioned(fig, points, path, plt)


def _save(fig, path: Path, plt) -> Path:
    """Write the figure as PNG to a temporary name beside ``path``, then rename it."""
    path = Path(path)
    tmp = path.with_name(path.name + ".partial")
    try:
        fig.tight_layout()
        fig.savefig(tmp, dpi=110, format="png")
        tmp.replace(path)
    finally:
        plt.close(fig)
        tmp.unlink(missing_ok=True)
    return path


def confusion_figure(calibration, path: Path) -> Path:
    """One heat map per calibrated factor, ``P(predicted | true)`` with counts, as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(calibration.factors)
    fig, axes = plt.subplots(1, len(names), figsize=(4.2 * len(names), 4.0))
    for ax, name in zip(np.atleast_1d(axes), names, strict=True):
        m = calibration.factors[name]
        probs = m.probabilities(0.0)
        ax.imshow(probs, vmin=0, vmax=1, cmap="Blues")
        for i in range(len(m.labels)):
            for j in range(len(m.labels)):
                ax.text(j, i, f"{probs[i, j]:.2f}\n({m.counts[i, j]})", ha="center",
                        va="center", fontsize=7,
                        color="white" if probs[i, j] > 0.6 else "black")
        ax.set_xticks(range(len(m.labels)), m.labels, rotation=45, ha="right", fontsize=8)
        ax.set_yticks(range(len(m.labels)), m.labels, fontsize=8)
        ax.set_title(f"{name} (accuracy {m.accuracy:.3f})", fontsize=10)
        ax.set_xlabel("perceived")
        ax.set_ylabel("true")
    return _save(fig, path, plt)


def learning_curve_figure(objective: Sequence[float], method: str, path: Path) -> Path:
    """The learner's objective per iteration, as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3.2))
    ax.plot(list(objective), ".-")
    ax.set_xlabel("iteration")
    ax.set_ylabel("objective (log posterior / log likelihood)")
    ax.set_title(method)
    ax.grid(alpha=0.3)
    return _save(fig, path, plt)


def confidence_figure(confidence: np.ndarray, policy: np.ndarray, state_names: Sequence[str],
                      action_names: Sequence[str], path: Path) -> Path:
    """``confidence[s, a]`` as a heat map, one row per state, the MAP policy's action ringed;
    the rows where it is below 0.9 are named in red. A PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    S, A = confidence.shape
    fig, ax = plt.subplots(figsize=(2.6 + 0.75 * A, 1.2 + 0.21 * S))
    ax.imshow(confidence, vmin=0, vmax=1, cmap="Blues", aspect="auto")
    for s in range(S):
        a = int(policy[s])
        ax.add_patch(plt.Rectangle((a - 0.5, s - 0.5), 1, 1, fill=False, lw=1.4, ec="darkorange"))
        ax.text(a, s, f"{confidence[s, a]:.2f}", ha="center", va="center", fontsize=6,
                color="white" if confidence[s, a] > 0.6 else "black")
    ax.set_xticks(range(A), list(action_names), rotation=35, ha="right", fontsize=8)
    ax.set_yticks(range(S), list(state_names), fontsize=6)
    for s, label in enumerate(ax.get_yticklabels()):
        if confidence[s, int(policy[s])] < 0.9:
            label.set_color("crimson")
    ax.set_title("posterior confidence per state (ringed: the learned policy's action)",
                 fontsize=9)
    return _save(fig, path, plt)


def precision_recall_figure(report: dict, folder: Path) -> list[Path]:
    """The inspection's precision-recall curves (``onionsort eval-perception``): one PNG per
    source (``inspection_pr_robot.png``, ``inspection_pr_human.png``), a curve per difficulty
    level for each fusion rule, the operating point at the report's threshold marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written = []
    for source in ("robot", "human"):
        levels = {lv: rows[source] for lv, rows in report["levels"].items() if source in rows}
        if not levels:
            continue
        rules = sorted({r for row in levels.values() for r in row["fused"]})
        fig, axes = plt.subplots(1, len(rules), figsize=(4.6 * len(rules), 4.0), squeeze=False)
        for ax, rule in zip(axes[0], rules, strict=True):
            for level, row in levels.items():
                fused = row["fused"].get(rule)
                if fused is None:
                    continue
                curve = fused["pr_curve"]
                line, = ax.plot(curve["recall"], curve["precision"], ".-", ms=3,
                                label=f"{level} ({fused['onions']} onions)")
                ax.plot([fused["recall"]], [fused["precision"]], "o", ms=8, mfc="none",
                        color=line.get_color())
            ax.set_xlim(0, 1.02)
            ax.set_ylim(0, 1.02)
            ax.set_xlabel("recall (blemished onions called blemished)")
            ax.set_ylabel("precision")
            ax.set_title(f"{source}'s inspection, fused by {rule}\n"
                         f"(circle: threshold {report['threshold']:.2f})", fontsize=9)
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7, loc="lower left")
        written.append(_save(fig, Path(folder) / f"inspection_pr_{source}.png", plt))
    return written


def sorting_scores_figure(rows: Sequence[dict], path: Path, *, title: str = "") -> Path:
    """Precision and recall of the Sawyer's sort per method, as a PNG: two bars per row
    (precision, recall), with their 95% intervals where a row has them (``precision_ci``,
    ``recall_ci``: ``[low, high]``), and the paper's values (a row's ``paper``: a dict of
    ``precision`` and ``recall``) as black diamonds.

    Parameters
    ----------
    rows : sequence of dict
        One per bar group: ``label``, ``precision``, ``recall``, optionally ``precision_ci``,
        ``recall_ci`` and ``paper``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not rows:
        raise ValueError("rows must hold at least one method's scores; got none")
    width = 0.36
    fig, ax = plt.subplots(figsize=(max(4.8, 1.5 * len(rows) + 1.6), 3.8))
    for j, (key, color) in enumerate((("precision", "C0"), ("recall", "C1"))):
        xs = np.arange(len(rows)) + (j - 0.5) * width
        values = np.array([r[key] for r in rows], float)
        low = np.array([r.get(f"{key}_ci", (v, v))[0] for r, v in zip(rows, values, strict=True)],
                       float)
        high = np.array([r.get(f"{key}_ci", (v, v))[1] for r, v in zip(rows, values,
                                                                         strict=True)], float)
        ax.bar(xs, values, width, color=color, label=key)
        has_ci = np.array([f"{key}_ci" in r for r in rows])
        if has_ci.any():
            ax.errorbar(xs[has_ci], values[has_ci],
                        yerr=[np.clip(values - low, 0, None)[has_ci],
                              np.clip(high - values, 0, None)[has_ci]],
                        fmt="none", ecolor="0.2", capsize=4, lw=1)
        paper = [(x, r["paper"][key]) for x, r in zip(xs, rows, strict=True) if r.get("paper")]
        if paper:
            ax.plot(*zip(*paper, strict=True), "D", color="black", ms=5,
                    label="paper (physical robot)" if j == 0 else None)
    ax.set_xticks(range(len(rows)), [r["label"] for r in rows], fontsize=8)
    ax.set_ylim(0, 1.22)  # room for the legend above the bars
    ax.set_yticks(np.linspace(0, 1, 6))
    ax.set_ylabel("fraction")
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=7, loc="upper center", ncol=3, frameon=False)
    ax.set_title(title or "the Sawyer's sort: precision and recall (95% interval where known)",
                 fontsize=9)
    return _save(fig, path, plt)
