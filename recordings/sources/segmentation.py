"""Cutting a plain video (no step clock) into the fixed-size steps perception reads.

A recorded session knows which step each frame belongs to; a video from a phone or a webcam does
not. Two ways to assign steps are offered, both as pure functions over lists:

* a **fixed clock** (:func:`fixed_clock`): a new step every ``step_seconds``;
* **perceived changes** (:func:`boundaries_from_labels`, then :func:`steps_from_boundaries`):
  a new step wherever a per-frame label (e.g. the perceived (onion, hand) location pair)
  changes and the new label holds for ``debounce`` frames, so that single-frame flicker of the
  perception does not cut steps.

:func:`resample_steps` then picks exactly ``frames_per_step`` frames of each step (phase 0 at
the step's first frame, the others spread over its motion), which is how the state classifier
reads a step, and :func:`boundary_scores` measures a segmentation against a known one.

Frames are numbered ``0 .. n_frames - 1``; a "boundary" is the index of a step's first frame.
"""

from __future__ import annotations

import itertools
import math
from bisect import bisect_left, bisect_right
from collections.abc import Hashable, Sequence

__all__ = [
    "boundaries_from_labels",
    "boundary_scores",
    "fixed_clock",
    "resample_steps",
    "split_long_steps",
    "steps_from_boundaries",
]


def fixed_clock(times_ns: Sequence[int], step_seconds: float) -> list[int]:
    """The step of each frame under a clock that starts a step every ``step_seconds``.

    Parameters
    ----------
    times_ns : sequence of int, shape (N,)
        Frame times, nanoseconds, non-decreasing (any origin; the first frame's time is step
        0's start).
    step_seconds : float
        Duration of a step, seconds (> 0).

    Returns
    -------
    list of int, shape (N,)
        ``floor((t - t_0) / step_seconds)`` per frame: non-decreasing from 0. A pause in the
        frames longer than a step skips step numbers; :func:`resample_steps` leaves such empty
        steps out.
    """
    if not (isinstance(step_seconds, (int, float)) and math.isfinite(step_seconds)
            and step_seconds > 0):
        raise ValueError(f"step_seconds must be a finite number > 0; got {step_seconds!r}")
    times = [int(t) for t in times_ns]
    for i in range(1, len(times)):
        if times[i] < times[i - 1]:
            raise ValueError(f"times_ns must be non-decreasing; got {times[i - 1]} then "
                             f"{times[i]} at frame {i}")
    if not times:
        return []
    step_ns = step_seconds * 1e9
    t0 = times[0]
    return [int((t - t0) // step_ns) for t in times]


def boundaries_from_labels(labels: Sequence[Hashable], *, debounce: int) -> list[int]:
    """Where new steps start, from a per-frame label sequence, ignoring short flicker.

    The label of frame 0 opens the first step. A different label starts a new step only once it
    has held for ``debounce`` consecutive frames; the boundary is then placed at the first frame
    of that run. A run shorter than ``debounce`` (flicker, or a label still unsettled at the
    end) changes nothing, and the step keeps its label.

    Parameters
    ----------
    labels : sequence of hashable, shape (N,)
        Any comparable-by-equality labels, e.g. ``(onion_location, hand_location)`` pairs.
    debounce : int
        Frames a new label must hold (>= 1; 1 counts every change).

    Returns
    -------
    list of int
        Strictly increasing frame indices, starting with 0; empty if ``labels`` is empty.

    Examples
    --------
    >>> boundaries_from_labels("aabaacccb", debounce=2)
    [0, 5]
    """
    if isinstance(debounce, bool) or not isinstance(debounce, int) or debounce < 1:
        raise ValueError(f"debounce must be an int >= 1; got {debounce!r}")
    labels = list(labels)
    if not labels:
        return []
    boundaries = [0]
    current = labels[0]
    run_start, run_label = None, None
    for i, label in enumerate(labels[1:], start=1):
        if label == current:
            run_start = None
            continue
        if run_start is None or label != run_label:
            run_start, run_label = i, label
        if i - run_start + 1 >= debounce:
            boundaries.append(run_start)
            current, run_start = label, None
    return boundaries


def steps_from_boundaries(n_frames: int, boundaries: Sequence[int]) -> list[int]:
    """The step of each frame, given where steps start.

    Parameters
    ----------
    n_frames : int
        Number of frames (>= 0).
    boundaries : sequence of int
        Strictly increasing frame indices in ``[0, n_frames)``; 0 is implied if absent.

    Returns
    -------
    list of int, shape (n_frames,)
        Step ``k`` for the frames from the ``k``-th boundary up to the next.
    """
    if int(n_frames) < 0:
        raise ValueError(f"n_frames must be >= 0; got {n_frames}")
    b = [int(x) for x in boundaries]
    if any(b[i] >= b[i + 1] for i in range(len(b) - 1)):
        raise ValueError(f"boundaries must be strictly increasing; got {b[:10]}")
    if b and (b[0] < 0 or b[-1] >= n_frames):
        raise ValueError(f"boundaries must lie in [0, {n_frames}); got {b[0]}..{b[-1]}")
    if n_frames == 0:
        return []
    if not b or b[0] != 0:
        b = [0, *b]
    steps = []
    for k, start in enumerate(b):
        end = b[k + 1] if k + 1 < len(b) else n_frames
        steps.extend([k] * (end - start))
    return steps


def split_long_steps(boundaries: Sequence[int], n_frames: int, *,
                     typical: float | None = None) -> list[int]:
    """Cut segments that last several typical steps into that many equal steps.

    Perceived changes miss the steps nobody can see: those during an occlusion, and those whose
    action leaves the picture as it was. Each still takes the sorter about as long as any
    other, so a segment ``k`` times the typical step length holds about ``k`` steps.

    Parameters
    ----------
    boundaries : sequence of int
        Strictly increasing frame indices where perceived steps start (0 implied).
    n_frames : int
    typical : float or None
        The typical step length in frames; None: the median length of the segments found.

    Returns
    -------
    list of int
        The boundaries, with a segment of ``L`` frames cut into ``round(L / typical)`` steps of
        (nearly) equal length where that is more than one.
    """
    starts = steps_from_boundaries(n_frames, boundaries)
    edges = [i for i in range(n_frames) if i == 0 or starts[i] != starts[i - 1]] + [n_frames]
    lengths = [b - a for a, b in itertools.pairwise(edges)]
    if not lengths:
        return []
    if typical is None:
        typical = float(sorted(lengths)[len(lengths) // 2])
    if not typical > 0:
        raise ValueError(f"typical must be > 0; got {typical}")
    out = []
    for start, length in zip(edges[:-1], lengths, strict=True):
        parts = max(1, round(length / typical))
        out.extend(start + (j * length) // parts for j in range(parts))
    return out


def resample_steps(step_of_frame: Sequence[int], frames_per_step: int) -> list[list[int]]:
    """Pick exactly ``frames_per_step`` frames of every step, spread evenly over the step.

    A step of ``n`` frames ``f_0 .. f_{n-1}`` gives phase ``k`` the frame
    ``f_{floor(k n / frames_per_step)}``: phase 0 is always the step's first frame (the state at
    rest) and the phases sample the step at the fractions ``k / frames_per_step`` of its
    length, as the simulator renders them. A step shorter than ``frames_per_step`` repeats
    frames (``n = 1`` gives ``[f_0] * frames_per_step``).

    Parameters
    ----------
    step_of_frame : sequence of int, shape (N,)
        Step of each frame, non-decreasing (gaps in the numbering, empty steps, are skipped).
    frames_per_step : int
        Frames per step (>= 1).

    Returns
    -------
    list of list of int, shape (T, frames_per_step)
        Frame indices of each non-empty step, steps in order, non-decreasing within a step.
    """
    if isinstance(frames_per_step, bool) or int(frames_per_step) < 1:
        raise ValueError(f"frames_per_step must be >= 1; got {frames_per_step}")
    m = int(frames_per_step)
    steps = [int(s) for s in step_of_frame]
    out: list[list[int]] = []
    start = 0
    for i in range(1, len(steps) + 1):
        if i < len(steps):
            if steps[i] < steps[i - 1]:
                raise ValueError(f"step_of_frame must be non-decreasing; got {steps[i - 1]} "
                                 f"then {steps[i]} at frame {i}")
            if steps[i] == steps[i - 1]:
                continue
        n = i - start
        out.append([start + (k * n) // m for k in range(m)])
        start = i
    return out


def boundary_scores(predicted: Sequence[int], truth: Sequence[int], *, tolerance: int = 1
                    ) -> dict[str, float | int]:
    """Precision and recall of predicted step boundaries against true ones.

    A predicted boundary matches a true boundary at most ``tolerance`` frames away; each
    boundary matches at most one other, the closest pairs first (greedy one-to-one matching by
    distance, ties by position). Frame 0, a boundary of every segmentation, counts like any
    other: leave it out of both lists to score the detected changes only.

    Parameters
    ----------
    predicted, truth : sequence of int
        Boundary frame indices (duplicates are counted once).
    tolerance : int
        Largest matching distance, frames (>= 0).

    Returns
    -------
    dict
        ``precision`` (matched / predicted), ``recall`` (matched / true), ``f1`` (their
        harmonic mean, 0 when both are 0), ``n_predicted``, ``n_true``, ``n_matched``. With no
        predicted (true) boundaries the precision (recall) is 1.0 if there are no true
        (predicted) boundaries either, else 0.0.
    """
    if isinstance(tolerance, bool) or int(tolerance) < 0:
        raise ValueError(f"tolerance must be >= 0; got {tolerance}")
    pred = sorted({int(x) for x in predicted})
    true = sorted({int(x) for x in truth})
    tol = int(tolerance)
    pairs = sorted((abs(p - t), p, t) for p in pred
                   for t in true[bisect_left(true, p - tol):bisect_right(true, p + tol)])
    used_p: set[int] = set()
    used_t: set[int] = set()
    for _, p, t in pairs:
        if p not in used_p and t not in used_t:
            used_p.add(p)
            used_t.add(t)
    matched = len(used_p)
    both_empty = 1.0 if not pred and not true else 0.0
    precision = matched / len(pred) if pred else both_empty
    recall = matched / len(true) if true else both_empty
    f1 = 2 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0
    return {"precision": precision, "recall": recall, "f1": f1, "n_predicted": len(pred),
            "n_true": len(true), "n_matched": matched}
