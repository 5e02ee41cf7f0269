"""Make the README's figures in ``docs/figures/``, and the record of how each was made.

- ``pipeline.png``: the pipeline, from the PyBullet world to the Sawyer's precision and recall,
  drawn with matplotlib (no data);
- ``efficiency.png``: normalized ILE and exact-policy rate against the number of
  demonstrations, per method (the four reward learners and behaviour cloning), at two noise
  levels: the data-efficiency sweep of docs/results.md's
  Results (``onionsort experiment sorting --trajectories 1,2,4,8 ...``, read from its
  ``summary.json``);
- ``workcell.png``: stills of the work cell rendered by the project's own cameras (TinyRenderer):
  a person sorting while a passer-by crosses the camera's view, what the camera sees at that
  moment, the Sawyer holding an onion up in the same cell, and its inspection camera's view.

Each figure made from a run knows the ``onionsort`` command that makes the run. A run missing
under ``--runs`` is made by running that command (``python -m onionsort.cli ...``; an
interrupted one is resumed), or with ``--no-run`` the script stops with one line naming the
command. A run folder that holds another sweep is refused. ``FIGURES.md`` beside the figures
lists each figure, the commands its data came from, and its seeds. PNGs are written through
a temporary name and optimized, the drawings as 64-colour palettes (the renders keep full
colour: their shading bands in a palette), so that all three stay under 200 KB.

Usage::

    python docs/make_figures.py                      # runs/ for the runs, docs/figures/ out
    python docs/make_figures.py --runs runs --out docs/figures --no-run
    python docs/make_figures.py --quick --runs /tmp/r --out /tmp/f   # tiny, for a test (~30 s)
"""

from __future__ import annotations

import argparse
import dataclasses
import io
import json
import logging
import subprocess
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

logger = logging.getLogger("make_figures")

#: The learners in the efficiency figure, in legend order, with their labels.
METHOD_LABELS = {
    "mmap-birl": "MMAP-BIRL",
    "map-birl": "MAP-BIRL (observations at face value)",
    "hidden-data-em": "HiddenDataEM",
    "maxent": "MaxEnt IRL",
    "bc": "behaviour cloning (face value)",
    "bc-em": "behaviour cloning (EM, through the observation model)",
}

#: Seeds of the work-cell still: the sorter's session and the Sawyer's line-up.
SESSION_SEED = 0
STATION_SEED = 5  # its line-up's first onion is blemished (FIGURES.md says so from the run)


@dataclass(frozen=True)
class RunSpec:
    """A run folder under ``--runs`` and the ``onionsort`` command that makes it.

    Attributes
    ----------
    name : str
        The folder's name under ``--runs``.
    args : tuple of str
        The command's arguments after ``onionsort``, without ``--out``.
    expect : dict
        What the run's ``summary.json`` ``config`` must hold (as JSON reads it back): a
        folder made by another command is refused, not plotted.
    """

    name: str
    args: tuple[str, ...]
    expect: dict

    def folder(self, runs: Path) -> Path:
        """The run's folder under ``runs``."""
        return Path(runs) / self.name

    def argv(self, runs: Path) -> list[str]:
        """The command's arguments after ``onionsort``, with ``--out``."""
        return [*self.args, "--out", str(self.folder(runs))]

    def command(self, runs: Path) -> str:
        """The command as a person types it."""
        return " ".join(["onionsort", *self.argv(runs)])


_EFFICIENCY_EXPECT = {"domain": "sorting", "seed": 0, "length": [20], "learners": ["x1"],
                      "methods": list(METHOD_LABELS)}
EFFICIENCY = RunSpec(
    "efficiency",
    ("experiment", "sorting", "--trajectories", "1,2,4,8", "--noise", "0.3,0.45",
     "--occlusion", "0.2", "--batches", "20", "--methods", ",".join(METHOD_LABELS)),
    {**_EFFICIENCY_EXPECT, "trajectories": [1, 2, 4, 8], "batches": 20,
     "points": [[0.2, 0.3], [0.2, 0.45]]},
)
"""The data-efficiency sweep of docs/results.md (about 3 min on 2 cores; every learner sees the
same data in every batch, so adding the cloning baselines left the other learners' cells as
they were)."""
EFFICIENCY_QUICK = RunSpec(
    "efficiency-quick",
    ("experiment", "sorting", "--trajectories", "1,2", "--noise", "0.3,0.45",
     "--occlusion", "0.2", "--batches", "2", "--workers", "1", "--methods",
     ",".join(METHOD_LABELS)),
    {**_EFFICIENCY_EXPECT, "trajectories": [1, 2], "batches": 2,
     "points": [[0.2, 0.3], [0.2, 0.45]]},
)
"""A tiny version of it, for ``--quick`` (seconds)."""


class FigureError(Exception):
    """A figure cannot be made; the message is one line that says what to do."""


# -- runs ------------------------------------------------------------------------------------

def ensure_run(spec: RunSpec, runs: Path, *, allow_run: bool = True) -> dict:
    """The ``summary.json`` of ``spec``'s run under ``runs``, running its command first if the
    run is missing (resumed if it was interrupted).

    Raises
    ------
    FigureError
        If the run is missing and ``allow_run`` is False (the message names the command), the
        command fails, or the folder holds a sweep other than ``spec``'s.
    """
    folder = spec.folder(runs)
    summary_path = folder / "summary.json"
    if not summary_path.exists():
        if not allow_run:
            raise FigureError(f"{summary_path} is missing; make it with: {spec.command(runs)}")
        argv = spec.argv(runs)
        if (folder / "results.csv.partial").exists():
            argv.append("--resume")  # an interrupted run: keep its finished trials
        logger.info("running: onionsort %s", " ".join(argv))
        done = subprocess.run([sys.executable, "-m", "onionsort.cli", *argv], check=False)
        if done.returncode != 0 or not summary_path.exists():
            raise FigureError(f"`onionsort {' '.join(argv)}` failed (exit code "
                              f"{done.returncode}); run it by hand to see why")
    try:
        summary = json.loads(summary_path.read_text())
        config = summary["config"]
    except (ValueError, KeyError, TypeError) as exc:
        raise FigureError(f"{summary_path} is not an experiment's summary ({exc}); remove "
                          f"{folder} and run: {spec.command(runs)}") from None
    wrong = {k: config.get(k) for k, v in spec.expect.items() if config.get(k) != v}
    if wrong:
        found = ", ".join(f"{k}={v}" for k, v in wrong.items())
        raise FigureError(f"{folder} holds another sweep ({found}); "
                          f"remove it, or give another --runs, and run: {spec.command(runs)}")
    return summary


# -- writing PNGs ----------------------------------------------------------------------------

def save_png(image, path: Path, *, colors: int | None = 64) -> Path:
    """Write ``image`` (a PIL image, or a matplotlib figure, closed after) to ``path`` as an
    optimized PNG through a temporary name: a palette of at most ``colors`` colours (drawings,
    whose flat colours and anti-aliased edges keep well in 64), or full RGB if None (renders,
    whose shading bands in a palette)."""
    from PIL import Image

    if not isinstance(image, Image.Image):
        import matplotlib.pyplot as plt

        buffer = io.BytesIO()
        try:
            image.savefig(buffer, format="png", dpi=100, facecolor="white")
        finally:
            plt.close(image)
        image = Image.open(io.BytesIO(buffer.getvalue()))
    image = image.convert("RGB")
    if colors is not None:
        image = image.quantize(colors=colors, method=Image.Quantize.MEDIANCUT)
    path = Path(path)
    tmp = path.with_name(path.name + ".partial")
    try:
        image.save(tmp, format="png", optimize=True)
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


# -- the pipeline ----------------------------------------------------------------------------

#: The diagram's boxes: key -> (centre x, centre y, width, title, body, kind), in the units of
#: a 100 x 56 canvas. ``kind`` picks the colours; a "side" box is dashed.
PIPELINE_BOXES = {
    "world": (10, 38, 18, "PyBullet world", "robot/: a person sorts\nonions (the expert)\n"
              "before an RGB-D camera;\na passer-by blocks it;\nconveyor, bin, Sawyer",
              "sim"),
    "record": (30, 38, 18, "record", "MCAP sessions:\nRGB-D, inspection\nview, step clock\n"
               "(+ ground truth\nin simulation)", "stage"),
    "perceive": (50, 38, 18, "perceive", "detector + state and\ninspection classifiers\n"
                 "→ noisy, occluded\nobservations\n(models: dataset, train)", "stage"),
    "learn": (70, 38, 18, "learn", "MMAP-BIRL marginalizes\noccluded and noisy\n"
              "steps (forward-backward);\nbaselines: MAP-BIRL,\nHiddenDataEM, MaxEnt", "learn"),
    "policy": (90, 38, 18, "reward & policy", "model.json: reward θ,\ngreedy policy;\n"
               "--posterior: samples,\npolicy confidence", "out"),
    "rerun": (10, 15, 18, "Rerun logging", "every stage logs its\nentity root (record/,\n"
              "perceive/, learn/,\nevaluate/) to .rrd", "side"),
    "import": (30, 15, 18, "import", "ROS bags, videos,\na camera → sensor-\nonly sessions",
               "side"),
    "calibrate": (50, 15, 18, "calibrate", "held-out labelled\nframes → confusion\n"
                  "matrices → observation\nmodel O[s, a, o]", "stage"),
    "evaluate": (90, 15, 18, "evaluate", "the Sawyer sorts with\nactive inspection\n"
                 "(turns each onion to\nits camera) → precision\nand recall", "sim"),
}
#: Arrows between boxes: (from, to, label, from side, to side); sides are "l", "r", "t", "b".
PIPELINE_ARROWS = [
    ("world", "record", "", "r", "l"),
    ("record", "perceive", "", "r", "l"),
    ("perceive", "learn", "", "r", "l"),
    ("learn", "policy", "", "r", "l"),
    ("import", "perceive", "", "t", "b"),
    ("calibrate", "learn", "O[s, a, o]", "r", "b"),
    ("policy", "evaluate", "greedy policy", "b", "t"),
]
_BOX_COLORS = {  # face, edge
    "sim": ("#e6f2e6", "#3a7d3a"), "stage": ("#e6eef8", "#2f5f9e"),
    "learn": ("#fdebd8", "#c46a12"), "out": ("#f2f2f2", "#555555"),
    "side": ("#ffffff", "#888888"),
}
_BOX_HEIGHT = 15.0


def _box_anchor(key: str, side: str) -> tuple[float, float]:
    x, y, w, *_ = PIPELINE_BOXES[key]
    return {"l": (x - w / 2, y), "r": (x + w / 2, y), "t": (x, y + _BOX_HEIGHT / 2),
            "b": (x, y - _BOX_HEIGHT / 2)}[side]


def pipeline_figure():
    """The pipeline diagram as a matplotlib figure (1000 x 560 px at 100 dpi)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import FancyArrowPatch, FancyBboxPatch

    fig = plt.figure(figsize=(10, 5.6))
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_xlim(0, 100)
    ax.set_ylim(0, 56)
    ax.axis("off")
    ax.text(1, 55, "onionsort: from a person's demonstrations to a robot that sorts",
            fontsize=12, weight="bold", va="top")
    ax.text(1, 51.3, "record, perceive, calibrate, learn, evaluate and import are commands "
            "(`onionsort COMMAND`) and stages (`onionsort.stages`); dashed: side inputs and "
            "logging", fontsize=8.5, color="0.35", va="top")
    for x, y, w, title, body, kind in PIPELINE_BOXES.values():
        face, edge = _BOX_COLORS[kind]
        ax.add_patch(FancyBboxPatch(
            (x - w / 2, y - _BOX_HEIGHT / 2), w, _BOX_HEIGHT,
            boxstyle="round,pad=0,rounding_size=1.2", facecolor=face, edgecolor=edge, linewidth=1.3,
            linestyle="--" if kind == "side" else "-"))
        ax.text(x, y + _BOX_HEIGHT / 2 - 1.2, title, ha="center", va="top", fontsize=10.5,
                weight="bold", color=edge if kind != "side" else "0.3")
        ax.text(x, y + _BOX_HEIGHT / 2 - 4.4, body, ha="center", va="top", fontsize=8.6,
                linespacing=1.25)
    for src, dst, label, s_side, d_side in PIPELINE_ARROWS:
        start, end = _box_anchor(src, s_side), _box_anchor(dst, d_side)
        style = "arc3" if s_side + d_side in ("rl", "tb", "bt") else "angle,angleA=0,angleB=90"
        ax.add_patch(FancyArrowPatch(start, end, arrowstyle="-|>", mutation_scale=14,
                                     linewidth=1.4, color="0.2", connectionstyle=style,
                                     shrinkA=1, shrinkB=1))
        if label:
            lx, ly = (end[0] - 1.0, start[1] + 0.6) if style != "arc3" else (
                (start[0] + end[0]) / 2 - 1.0, (start[1] + end[1]) / 2)
            ax.text(lx, ly, label, fontsize=8.6, style="italic", ha="right",
                    va="bottom" if style != "arc3" else "center", color="0.2")
    ax.text(99, 1.2, "`onionsort experiment`: the learners alone, on demonstrations sampled "
            "from the task's MDP (efficiency.png)", fontsize=8, color="0.35", ha="right")
    return fig


# -- the efficiency curve --------------------------------------------------------------------

def efficiency_figure(points: Sequence[dict]):
    """Normalized ILE (top) and exact-policy rate (bottom) against demonstrations per batch,
    one column per noise level, one line per method with 95% bootstrap error bars.

    Parameters
    ----------
    points : sequence of dict
        The ``points`` of an experiment's ``summary.json`` (``irl.experiments.summarize``), all
        at one occlusion rate and length.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from onionsort.plots import COLORS, MARKERS

    points = list(points)
    if not points:
        raise FigureError("the summary holds no points to plot")
    for key in ("occlusion", "length", "learner"):
        values = sorted({p[key] for p in points})
        if len(values) > 1:
            raise FigureError(f"efficiency_figure plots one {key}; the summary has {values}")
    noises = sorted({p["noise"] for p in points})
    ticks = sorted({p["trajectories"] for p in points})
    methods = [m for m in METHOD_LABELS if any(p["method"] == m for p in points)]
    fig, axes = plt.subplots(2, len(noises), figsize=(9, 6.2), sharex=True, sharey="row",
                             squeeze=False, gridspec_kw={"height_ratios": [1.6, 1]})
    ile_top = max(p["normalized_ile_ci_high"] for p in points)
    for j, noise in enumerate(noises):
        for i, (mean, ci) in enumerate((("normalized_ile_mean", "normalized_ile_ci"),
                                         ("exact_policy_rate", "exact_policy_ci"))):
            ax = axes[i][j]
            for m, method in enumerate(methods):
                rows = sorted((p for p in points if p["method"] == method
                               and p["noise"] == noise), key=lambda p: p["trajectories"])
                xs = np.array([p["trajectories"] for p in rows], float)
                xs *= 2.0 ** (0.07 * (m - (len(methods) - 1) / 2))  # dodge: equal means show
                ys = np.array([p[mean] for p in rows])
                err = np.array([ys - [p[f"{ci}_low"] for p in rows],
                                [p[f"{ci}_high"] for p in rows] - ys])
                ours = method == "mmap-birl"  # drawn on top, a little heavier
                ax.errorbar(xs, ys, yerr=np.clip(err, 0, None), color=COLORS[method],
                            marker=MARKERS[method], ms=5.5 if ours else 5,
                            lw=2.2 if ours else 1.5, capsize=2.5, elinewidth=1,
                            zorder=3 if ours else 2, label=METHOD_LABELS[method])
            ax.set_xscale("log", base=2)
            ax.set_xticks(ticks, [str(t) for t in ticks])
            ax.minorticks_off()
            ax.grid(alpha=0.3)
            if i == 0:
                ax.set_ylim(-1, max(5.0, ile_top * 1.08))
                ax.set_title(f"observation noise {noise:.0%}", fontsize=11)
            else:
                ax.set_ylim(-0.03, 1.05)
                ax.set_xlabel(f"demonstrations ({points[0]['length']} steps each) per batch")
            if j == 0:
                ax.set_ylabel("normalized ILE (%)\n(lower is better)" if i == 0 else
                              "exact-policy rate\n(higher is better)")
    p0 = points[0]
    batches = sorted({p["batches"] for p in points})
    fig.suptitle(f"Onion sorting at {p0['occlusion']:.0%} occlusion: learning from few "
                 "demonstrations", fontsize=12.5, weight="bold", y=0.985)
    fig.text(0.5, 0.935, f"mean over {'-'.join(map(str, batches))} batches (each learner on "
             "the same data); bars: 95% percentile-bootstrap intervals over batches",
             ha="center", fontsize=9, color="0.35")
    handles, labels = axes[0][0].get_legend_handles_labels()
    ncol = len(methods) if len(methods) <= 4 else 3  # the cloning baselines: two rows
    rows = -(-len(methods) // ncol)
    fig.legend(handles, labels, loc="lower center", ncol=ncol, fontsize=9,
               frameon=False, bbox_to_anchor=(0.5, 0.005))
    fig.subplots_adjust(left=0.1, right=0.985, top=0.86, bottom=0.125 + 0.04 * rows,
                        hspace=0.08, wspace=0.05)
    return fig


def efficiency_table(points: Sequence[dict]) -> list[str]:
    """The efficiency figure's means as Markdown table lines: normalized ILE % and
    exact-policy rate per (noise, demonstrations) and method."""
    methods = [m for m in METHOD_LABELS if any(p["method"] == m for p in points)]
    lines = ["| noise | demos | " + " | ".join(methods) + " |",
             "|---|---|" + "---|" * len(methods)]
    for noise in sorted({p["noise"] for p in points}):
        for n in sorted({p["trajectories"] for p in points}):
            cells = []
            for m in methods:
                row = next(p for p in points if p["method"] == m and p["noise"] == noise
                           and p["trajectories"] == n)
                cells.append(f"{row['normalized_ile_mean']:.1f} · "
                             f"{row['exact_policy_rate']:.2f}")
            lines.append(f"| {noise:.0%} | {n} | " + " | ".join(cells) + " |")
    return lines


# -- the work cell ---------------------------------------------------------------------------

def _overview_camera(width: int, height: int):
    """A camera beside and above the cell that sees the belt, the bin, the person (or the
    Sawyer) and the passer-by."""
    from robot.camera import CameraSpec

    return CameraSpec(width=width, height=height, fov_deg=34.0, eye=(2.1, -1.9, 2.0),
                      target=(0.1, 0.05, 1.05), frame_id="overview")


def _sorter_stills(size: tuple[int, int], seed: int) -> tuple[np.ndarray, np.ndarray, dict]:
    """The overview and the recorder's camera (:class:`robot.camera.CameraSpec`'s pose) at
    the moment of a recorded session when the passer-by blocks least of the camera's view while
    the person holds an onion up to inspect it (else, least of all occluded frames).

    The session runs twice from ``seed``: once at the recorder's resolution to find the
    moment, then again to render it at ``size``.
    """
    from irl.domains.onion_sorting import Location, decode_state
    from robot.camera import CameraSpec, render
    from robot.simulation import SessionConfig, SortingSession, expert_model

    policy, initial = expert_model()
    config = SessionConfig(n_steps=20, occlusion=0.3)
    with SortingSession(config, policy, initial, seed=seed) as session:
        scores = {f.index: (decode_state(f.step.state).onion != Location.FACE,
                            f.occluded_fraction)
                  for f in session.frames() if f.step.occluded}
    if not scores:
        raise FigureError(f"session seed {seed} has no occluded step; choose another seed")
    index = min(scores, key=scores.get)
    width, height = size
    camera = dataclasses.replace(CameraSpec(), width=width, height=height)
    with SortingSession(config, policy, initial, seed=seed) as session:
        for frame in session.frames():
            if frame.index == index:
                overview = render(session.client, _overview_camera(width, height),
                                  session.lighting).rgb
                view = render(session.client, camera, session.lighting).rgb
                break
    about = {"session seed": seed, "session occlusion": config.occlusion, "frame": index,
             "camera blocked": f"{scores[index][1]:.0%}"}
    return overview, view, about


def _station_stills(size: tuple[int, int], seed: int, quick: bool
                    ) -> tuple[np.ndarray, np.ndarray, dict]:
    """The overview of the Sawyer holding the first onion of its line-up up to its inspection
    camera after CLAIM, PICK and INSPECT, and the inspection view that shows the most rot."""
    from irl.domains.onion_sorting import SortAction
    from robot.camera import render
    from robot.classifier import GROUND_TRUTH
    from robot.station import SawyerStation
    from robot.station_cameras import ROBOT_INSPECTION_CAMERA

    width, height = size
    inspection = dataclasses.replace(ROBOT_INSPECTION_CAMERA, width=width, height=height)
    with SawyerStation(GROUND_TRUTH, n_onions=6, n_blemished=3, seed=seed,
                       inspection=inspection, label_blemishes=True,
                       move_steps=40 if quick else 120) as station:
        for action in (SortAction.CLAIM, SortAction.PICK, SortAction.INSPECT):
            station.step(action)
        overview = render(station.client, _overview_camera(width, height),
                          station.lighting).rgb
        rot = [sum(label.rot_pixels or 0 for label in labels)
               for labels in station.last_labels]
        k = int(np.argmax(rot))
        view = station.last_views[k].rgb
        blemished = bool(station.blemished[0])
    about = {"station seed": seed, "onion": "blemished" if blemished else "good",
             "inspection view": f"{k + 1} of {len(rot)}"}
    return overview, view, about


def workcell_image(size: tuple[int, int] = (480, 360), *, quick: bool = False):
    """Four stills in a 2 x 2 grid with captions, as a PIL image; returns it and what was
    rendered (seeds, frame).

    Top: the sorter's session seen from beside the cell, and the recorder's camera at the
    same moment. Bottom: the Sawyer in the same cell holding an onion up, and its inspection
    camera's view of the onion.
    """
    from matplotlib import font_manager
    from PIL import Image, ImageDraw, ImageFont

    w, h = size
    sorter_overview, sorter_view, about_sorter = _sorter_stills(size, SESSION_SEED)
    robot_overview, robot_view, about_robot = _station_stills(size, STATION_SEED, quick)
    captions = [
        "A person sorts; a passer-by crosses the camera's view",
        f"The recorder's camera then: {about_sorter['camera blocked']} of it blocked",
        "The Sawyer in the same cell holds an onion up",
        f"Its inspection camera (view {about_robot['inspection view']}): a "
        f"{about_robot['onion']} onion",
    ]
    title = "The work cell, rendered by onionsort's cameras (PyBullet TinyRenderer)"
    pad, caption = max(4, w // 60), max(16, h // 13)
    top = max(20, h // 9)
    canvas = Image.new("RGB", (2 * w + 3 * pad, top + 2 * (h + caption) + pad), "white")
    draw = ImageDraw.Draw(canvas)
    font_path = font_manager.findfont("DejaVu Sans")

    def fitting(size: int, texts: list[str], width: int):
        """The font at ``size`` px, or smaller until every text fits ``width``."""
        font = ImageFont.truetype(font_path, size)
        while size > 6 and max(draw.textlength(t, font=font) for t in texts) > width:
            size -= 1
            font = ImageFont.truetype(font_path, size)
        return font

    font = fitting(max(10, h // 22), captions, w)
    draw.text((pad, pad // 2), title, font=fitting(max(12, h // 17), [title], canvas.width),
              fill=(20, 20, 20))
    for k, (image, text) in enumerate(zip(
            (sorter_overview, sorter_view, robot_overview, robot_view), captions, strict=True)):
        x = pad + (k % 2) * (w + pad)
        y = top + (k // 2) * (h + caption)
        draw.text((x, y + caption // 2), text, font=font, fill=(40, 40, 40), anchor="lm")
        canvas.paste(Image.fromarray(image), (x, y + caption))
        draw.rectangle((x - 1, y + caption - 1, x + w, y + caption + h), outline=(160, 160, 160))
    return canvas, {**about_sorter, **about_robot}


# -- the record ------------------------------------------------------------------------------

#: What FIGURES.md says of the viewer's picture, which a script of its own makes.
VIEWER_NOTE = (
    "The demo's evaluation recording (`runs/demo/mmap-birl/evaluation.rrd`) as Rerun's web "
    "viewer shows it, made by `python docs/make_viewer_figure.py` (headless Chromium and the "
    "`playwright` package; it runs `onionsort demo --out runs/demo` when the run is missing).")

def write_record(out: Path, entries: list[dict], invocation: str, table: list[str]) -> Path:
    """Write ``FIGURES.md``: each figure, what it shows, the commands its data came from, its
    seeds and size; and the efficiency figure's means."""
    lines = ["# The README's figures", "",
             f"Made by `{invocation}` (this file is written with them). A figure made from a "
             "run names the command that makes the run; the script runs it when the run is "
             "missing.", ""]
    for e in entries:
        lines += [f"## {e['file']}", "", e["what"], ""]
        if e["commands"]:
            lines += ["Data:", "", *(f"    {c}" for c in e["commands"]), ""]
        else:
            lines += ["Data: none; the script makes it itself.", ""]
        if e.get("seeds"):
            lines += ["Seeds and settings: " + ", ".join(f"{k} {v}" for k, v in
                                                        e["seeds"].items()) + ".", ""]
        lines += [f"Size: {e['size_kb']:.0f} KB, {e['pixels'][0]} x {e['pixels'][1]} px.", ""]
    if (Path(out) / "viewer.png").exists():
        lines += ["## viewer.png", "", VIEWER_NOTE, ""]
    if table:
        lines += ["## The efficiency figure's numbers", "",
                  "Mean normalized ILE (%) · exact-policy rate, per method:", "", *table, ""]
    from onionsort.stages.base import write_text

    return write_text(Path(out) / "FIGURES.md", "\n".join(lines))


def make_figures(runs: Path, out: Path, *, quick: bool = False, allow_run: bool = True,
                 invocation: str = "python docs/make_figures.py") -> list[dict]:
    """Make the three figures and ``FIGURES.md`` in ``out``; returns one entry per figure
    (file, what it shows, commands, seeds, size)."""
    from PIL import Image

    spec = EFFICIENCY_QUICK if quick else EFFICIENCY
    summary = ensure_run(spec, runs, allow_run=allow_run)  # before the renders: fail early
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    entries = []

    path = save_png(pipeline_figure(), out / "pipeline.png", colors=64)
    entries.append({"file": path.name, "commands": [], "what": (
        "The pipeline: the PyBullet world, the stages `record`, `perceive`, `calibrate`, "
        "`learn` and `evaluate`, with `import` and Rerun logging beside them.")})

    path = save_png(efficiency_figure(summary["points"]), out / "efficiency.png", colors=64)
    entries.append({"file": path.name, "commands": [spec.command(runs)],
                    "seeds": {"sweep seed": summary["config"]["seed"]}, "what": (
        "Normalized ILE (%) and exact-policy rate against the number of demonstrations, per "
        "method, at 30% and 45% observation noise and 20% occlusion (docs/results.md's "
        "data-efficiency table), with 95% percentile-bootstrap intervals over batches.")})

    image, about = workcell_image((240, 180) if quick else (480, 360), quick=quick)
    path = save_png(image, out / "workcell.png", colors=None)
    entries.append({"file": path.name, "commands": [], "seeds": about, "what": (
        "Stills rendered by the script from the project's PyBullet world: a recorded "
        "session (`robot.simulation.SortingSession`, its default configuration at 30% "
        "occlusion) at the occluded frame where the person holds an onion up and the "
        "passer-by blocks least, seen from beside the cell and by the recorder's camera; "
        "and the Sawyer station (`robot.station.SawyerStation`) after CLAIM, PICK and INSPECT "
        "of its first onion, with the inspection view that shows the most rot.")})
    for e in entries:
        file = out / e["file"]
        e["size_kb"] = file.stat().st_size / 1024
        with Image.open(file) as im:
            e["pixels"] = im.size
    write_record(out, entries, invocation, efficiency_table(summary["points"]))
    return entries


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="make_figures", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=Path, default=Path("runs"),
                        help="folder of the runs the figures read (made when missing)")
    parser.add_argument("--out", type=Path, default=Path("docs/figures"),
                        help="folder of the figures and FIGURES.md")
    parser.add_argument("--quick", action="store_true",
                        help="a tiny sweep and small renders, for a test")
    parser.add_argument("--no-run", action="store_true",
                        help="fail, naming the command, instead of making a missing run")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    invocation = " ".join(["python docs/make_figures.py", "--runs", str(args.runs),
                           "--out", str(args.out), *(["--quick"] if args.quick else [])])
    try:
        entries = make_figures(args.runs, args.out, quick=args.quick,
                               allow_run=not args.no_run, invocation=invocation)
    except FigureError as exc:
        print(f"make_figures: error: {exc}", file=sys.stderr)
        return 2
    for e in entries:
        print(f"{args.out / e['file']}: {e['size_kb']:.0f} KB, "
              f"{e['pixels'][0]} x {e['pixels'][1]} px")
    print(f"{args.out / 'FIGURES.md'}: the commands and seeds")
    return 0


if __name__ == "__main__":
    sys.exit(main())
