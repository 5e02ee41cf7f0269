"""The one helper that turns a seed into a random generator."""

from __future__ import annotations

import numpy as np

__all__ = ["check_random_state"]


def check_random_state(
    seed: int | np.random.Generator | None, name: str = "seed"
) -> np.random.Generator:
    """Return a ``np.random.Generator`` for ``seed`` (an int >= 0, a generator, or None).

    ``name`` is the argument's name in the error messages.
    """
    if isinstance(seed, np.random.Generator):
        return seed
    if seed is None:
        return np.random.default_rng()
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)):
        raise TypeError(
            f"{name} must be an int, a numpy Generator or None; got {type(seed).__name__} "
            f"{seed!r}"
        )
    if seed < 0:
        raise ValueError(f"{name} must be a non-negative int; got {seed}")
    return np.random.default_rng(int(seed))
