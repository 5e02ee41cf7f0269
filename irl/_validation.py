"""Input checks shared by the public constructors and ``fit`` methods.

One error format throughout: the argument's name, what is expected, and what was given, in one
line; ``TypeError`` for a value of the wrong kind, ``ValueError`` for a value out of range.
"""

from __future__ import annotations

import numbers

import numpy as np
import scipy.sparse as sp

from irl._random import check_random_state

__all__ = [
    "as_float_array",
    "as_index_array",
    "check_int",
    "check_probability_rows",
    "check_random_state",
    "check_real",
    "describe",
]

ROW_SUM_TOL = 1e-6


def describe(value) -> str:
    """A short ``type value`` description of what was given, for error messages."""
    text = " ".join(repr(value).split())  # one line, whatever the repr
    if len(text) > 60:
        text = text[:57] + "..."
    return f"{type(value).__name__} {text}"


def check_real(
    value, name: str, *, low: float | None = None, high: float | None = None,
    low_open: bool = False, high_open: bool = False,
) -> float:
    """``value`` as a finite float within the given bounds, or raise.

    ``TypeError`` unless it is a real number (a bool is not); ``ValueError`` unless it is finite
    and within ``[low, high]`` (an open end with ``low_open``/``high_open``).
    """
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a real number; got {describe(value)}")
    x = float(value)
    parts = []
    if low is not None:
        parts.append(f"{'>' if low_open else '>='} {low}")
    if high is not None:
        parts.append(f"{'<' if high_open else '<='} {high}")
    if low is not None and high is not None:
        what = f"in {'(' if low_open else '['}{low}, {high}{')' if high_open else ']'}"
    else:
        what = f"a finite number {parts[0] if parts else ''}".rstrip()
    if not np.isfinite(x):
        raise ValueError(f"{name} must be {what}; got {x!r}")
    if (low is not None and (x < low or (low_open and x == low))) or (
        high is not None and (x > high or (high_open and x == high))
    ):
        raise ValueError(f"{name} must be {what}; got {x!r}")
    return x


def check_int(value, name: str, *, low: int | None = None, high: int | None = None) -> int:
    """``value`` as an int within ``[low, high]``; ``TypeError`` for a non-integer or a bool."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an integer; got {describe(value)}")
    n = int(value)
    if (low is not None and n < low) or (high is not None and n > high):
        rule = (f">= {low}" if high is None else
                f"<= {high}" if low is None else f"in [{low}, {high}]")
        raise ValueError(f"{name} must be an integer {rule}; got {n}")
    return n


def as_float_array(value, name: str, *, ndim: int | None = None) -> np.ndarray:
    """``value`` as a float ndarray (finite), optionally of ``ndim`` dimensions, or raise."""
    if value is None or isinstance(value, (str, bytes, dict, set)):
        raise TypeError(f"{name} must be an array of numbers; got {describe(value)}")
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be an array of numbers; got {describe(value)} ({exc})") \
            from None
    if ndim is not None and arr.ndim != ndim:
        raise ValueError(f"{name} must have {ndim} dimension(s); got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite; got NaN or inf entries")
    return arr


def as_index_array(value, name: str, *, size: int) -> np.ndarray:
    """A 1-D array of integer indices in ``[0, size)``, or raise naming ``name``."""
    if value is None or isinstance(value, (str, bytes, dict, set)):
        raise TypeError(f"{name} must be a 1-D array of integer indices; got {describe(value)}")
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:  # ragged input
        raise TypeError(f"{name} must be a 1-D array of integer indices; got {exc}") from None
    if arr.dtype == bool or not (np.issubdtype(arr.dtype, np.integer) or arr.size == 0):
        raise TypeError(
            f"{name} must be a 1-D array of integer indices; got dtype {arr.dtype}"
        )
    if arr.ndim != 1 or arr.size == 0:
        raise ValueError(f"{name} must be a non-empty 1-D array of indices; got shape {arr.shape}")
    if arr.min() < 0 or arr.max() >= size:
        bad = arr[(arr < 0) | (arr >= size)][0]
        raise ValueError(f"{name} must lie in [0, {size}); got {int(bad)}")
    return arr.astype(np.int64)


def check_probability_rows(probs, name: str, tol: float = ROW_SUM_TOL) -> None:
    """Raise ``ValueError`` unless every row of ``probs`` (last axis) is a distribution.

    ``probs`` is a dense array whose last axis is the outcome, or a 2-D sparse matrix.
    The message names the argument and the first offending row.
    """
    if sp.issparse(probs):
        data = probs.data
        if data.size and not np.all(np.isfinite(data)):
            raise ValueError(f"{name} must be finite; found NaN or inf")
        if data.size and data.min() < 0:
            raise ValueError(f"{name} must be non-negative; found {data.min():.6g}")
        sums = np.asarray(probs.sum(axis=1)).ravel()
        shape = (probs.shape[0],)
    else:
        probs = np.asarray(probs)
        if not np.all(np.isfinite(probs)):
            raise ValueError(f"{name} must be finite; found NaN or inf")
        if probs.size and probs.min() < 0:
            idx = np.unravel_index(np.argmin(probs), probs.shape)
            raise ValueError(
                f"{name} must be non-negative; {name}[{', '.join(map(str, idx))}] = "
                f"{probs[idx]:.6g}"
            )
        sums = probs.sum(axis=-1)
        shape = sums.shape
    bad = np.flatnonzero(np.abs(sums - 1.0).ravel() > tol)
    if bad.size:
        idx = np.unravel_index(bad[0], shape)
        raise ValueError(
            f"{name} rows must sum to 1 over the last axis; row {tuple(int(i) for i in idx)} "
            f"sums to {sums.ravel()[bad[0]]:.6g} ({bad.size} bad rows)"
        )
