"""An observer failure that lasts a whole demonstration: every observation read through a swap.

Layout: ``permutation[o]``, the observation reported when the observer would have reported
``o``.

The observation models of :mod:`irl.observation` treat each step's misreading as independent of
the others. Some failures are not: a camera whose colour balance is off for a whole session can
read every good onion as blemished and every blemished one as good. Fourteen such reads are, to
a model of independent errors, overwhelming evidence for the reward that sorts backwards.
:class:`SessionSwap` says instead that with probability ``rate`` a whole demonstration was read
through ``permutation``, so a demonstration's likelihood is the mixture

    P_swap(o | theta) = (1 - rate) P(o | theta) + rate P(permutation(o) | theta)

(:class:`irl.MMAPBIRL`'s ``session_swap``), each term by forward-backward through the
observation model. A reading impossible under that model (an observation of probability 0,
which calibration's smoothing prevents) stops the fit with the usual error. Since the
permutation is an involution (a swap of two values), ``permutation(o)`` is also the
observation the observer would have reported.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from irl._validation import check_real
from irl.demonstrations import Demonstration

__all__ = ["SessionSwap", "value_swap"]


@dataclass(frozen=True, eq=False)
class SessionSwap:
    """With probability ``rate``, each demonstration's observations were all read through
    ``permutation`` (an involution of the observation indices: ``permutation[permutation]``
    is the identity).

    Attributes
    ----------
    permutation : ndarray of int, shape (n_observations,)
    rate : float in (0, 1)
        The prior probability that a demonstration was read swapped.
    """

    permutation: np.ndarray
    rate: float

    def __post_init__(self) -> None:
        perm = np.asarray(self.permutation)
        if perm.ndim != 1 or not perm.size or not np.issubdtype(perm.dtype, np.integer):
            raise ValueError(f"permutation must be a 1-D array of observation indices; got "
                             f"shape {perm.shape} of {perm.dtype}")
        perm = perm.astype(np.int64)
        if not np.array_equal(np.sort(perm), np.arange(perm.size)):
            raise ValueError("permutation must hold every observation index exactly once")
        if not np.array_equal(perm[perm], np.arange(perm.size)):
            raise ValueError("permutation must be its own inverse (a swap of values)")
        perm.setflags(write=False)
        object.__setattr__(self, "permutation", perm)
        object.__setattr__(self, "rate", check_real(self.rate, "rate", low=0.0, high=1.0,
                                                    low_open=True, high_open=True))

    @property
    def n_observations(self) -> int:
        return int(self.permutation.size)

    def apply(self, demo: Demonstration) -> Demonstration:
        """``demo`` read through the swap (occluded steps stay occluded)."""
        if any(o is not None and o >= self.n_observations for o in demo.observations):
            raise ValueError(f"the demonstration has observations outside [0, "
                             f"{self.n_observations}) that the swap covers")
        return Demonstration([None if o is None else int(self.permutation[o])
                              for o in demo.observations])


def value_swap(task, factor: str, values: tuple[str, str], rate: float) -> SessionSwap:
    """The :class:`SessionSwap` of ``task``'s pair observations that exchanges two values of
    one state factor (for onion sorting, ``("prediction", ("good", "bad"))``: the onion's class
    read backwards), everything else read as it was.

    Parameters
    ----------
    task : irl.TaskDescription
        Whose pair observations ``o = s * A + a`` are permuted.
    factor : str
        The state factor read backwards.
    values : tuple of two str
        The two values of ``factor`` that are exchanged.
    rate : float in (0, 1)
        The prior probability that a demonstration was read swapped.

    Returns
    -------
    SessionSwap
    """
    a, b = (task.value_index(factor, v) for v in values)
    if a == b:
        raise ValueError(f"values must name two different values of {factor!r}; got {values}")
    f = task.factor_names.index(factor)
    states = task.decode_array(np.arange(task.n_states))
    col = states[:, f].copy()
    states[:, f] = np.where(col == a, b, np.where(col == b, a, col))
    swapped = task.encode_array(states)
    pairs = np.arange(task.n_pairs)
    s, act = np.divmod(pairs, task.n_actions)
    return SessionSwap(swapped[s] * task.n_actions + act, rate)
