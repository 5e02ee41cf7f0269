"""Grouping frames into steps: the one place that knows how a step's frames are found.

A session (and a dataset made of sessions) is a sequence of frames, each tagged with the abstract
step it belongs to and its phase (position) within that step; phase 0 shows the state at rest.
Perception reads whole steps, so the frames of one step must be collected and put in phase order,
and a step with the wrong number of frames must be noticed. :func:`group_steps` does that for
any kind of frame, given how to read its step and phase.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable, Hashable, Iterable
from typing import TypeVar

__all__ = ["group_steps"]

F = TypeVar("F")


def group_steps(
    frames: Iterable[F], *, step: Callable[[F], Hashable], phase: Callable[[F], int],
    frames_per_step: int, incomplete: str = "raise", source: str = "frames",
) -> list[tuple[Hashable, list[F]]]:
    """Collect frames into steps, each in phase order, steps in sorted order.

    Parameters
    ----------
    frames : iterable
        Frames in any order.
    step, phase : callable
        The step key (an int, or e.g. ``(session, step)``) and the phase of a frame.
    frames_per_step : int
        How many frames a complete step has; its phases must be ``0 .. frames_per_step - 1``.
    incomplete : {"raise", "drop"}
        What to do with a step whose phases are not exactly ``0 .. frames_per_step - 1``:
        raise a ValueError naming it, or leave it out (a dataset cut short by its frame count
        ends in a partial step).
    source : str
        What the frames are, for error messages (e.g. the file's path).

    Returns
    -------
    list of (key, frames)
        One entry per complete step, sorted by key; ``frames`` sorted by phase.
    """
    if frames_per_step < 1:
        raise ValueError(f"frames_per_step must be >= 1; got {frames_per_step}")
    if incomplete not in ("raise", "drop"):
        raise ValueError(f"incomplete must be 'raise' or 'drop'; got {incomplete!r}")
    by_step: dict[Hashable, list[F]] = defaultdict(list)
    for frame in frames:
        by_step[step(frame)].append(frame)
    out = []
    expected = list(range(frames_per_step))
    for key in sorted(by_step):
        members = sorted(by_step[key], key=phase)
        phases = [int(phase(f)) for f in members]
        if phases != expected:
            if incomplete == "drop":
                continue
            raise ValueError(
                f"{source}: step {key} has frames of phases {phases}; a step must have "
                f"{frames_per_step} frames of phases 0..{frames_per_step - 1}")
        out.append((key, members))
    return out
