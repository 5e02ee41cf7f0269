"""Figures (matplotlib, written as PNG): experiment sweeps, confusion matrices, learning curves."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

COLORS = {"mmap-birl": "C0", "map-birl": "C1", "hidden-data-em": "C3", "maxent": "C2"}


def _series(results, x_attr, y_attr, method, **fixed):
    xs = sorted({getattr(r, x_attr) for r in results
                 if r.method == method and all(getattr(r, k) == v for k, v in fixed.items())})
    mean, low, high = [], [], []
    for x in xs:
        ys = [getattr(r, y_attr) for r in results if r.method == method
              and getattr(r, x_attr) == x and all(getattr(r, k) == v for k, v in fixed.items())]
        mean.append(np.mean(ys))
        low.append(np.percentile(ys, 25))
        high.append(np.percentile(ys, 75))
    return np.array(xs), np.array(mean), np.array(low), np.array(high)


def _panel(ax, results, x_attr, y_attr, fixed, xlabel, ylabel):
    for method in sorted({r.method for r in results}):
        xs, m, lo, hi = _series(results, x_attr, y_attr, method, **fixed)
        if len(xs) == 0:
            continue
        ax.plot(xs * 100, m, "o-", color=COLORS.get(method), label=method)
        ax.fill_between(xs * 100, lo, hi, color=COLORS.get(method), alpha=0.15)
    # ILE spans orders of magnitude between methods; symlog keeps 0 and outliers readable.
    ax.set_yscale("symlog", linthresh=0.01 if y_attr == "ile" else 0.001)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)


def plot_sweep(results: Sequence, out: Path, *, title: str = "") -> list[Path]:
    """ILE vs occlusion per noise level, ILE vs noise without occlusion, and run time vs
    occlusion: lines are means over batches, bands the interquartile range. Returns the files
    written."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written = []
    noises = sorted({r.noise for r in results if r.occlusion > 0})
    occluded = [r for r in results if r.occlusion > 0]
    for y_attr, ylabel, what, name in (
        ("ile", "ILE", "", "ile_vs_occlusion.png"),
        ("seconds", "fit time (s)", "run time, ", "seconds_vs_occlusion.png"),
    ):
        if not noises:
            break
        fig, axes = plt.subplots(1, len(noises), figsize=(4.5 * len(noises), 3.6), squeeze=False)
        for ax, noise in zip(axes[0], noises, strict=True):
            _panel(ax, occluded, "occlusion", y_attr, {"noise": noise}, "occlusion (%)", ylabel)
            ax.set_title(f"{title}: {what}noise {noise:.0%}")
        written.append(_save(fig, out / name, plt))
    if len({r.noise for r in results if r.occlusion == 0}) > 1:
        fig, ax = plt.subplots(figsize=(4.5, 3.6))
        _panel(ax, [r for r in results if r.occlusion == 0], "noise", "ile", {},
               "observation noise (%)", "ILE")
        ax.set_title(f"{title}: no occlusion")
        written.append(_save(fig, out / "ile_vs_noise.png", plt))
    return written


def _save(fig, path: Path, plt) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
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
