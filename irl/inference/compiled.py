"""The numba backend of forward-backward: which backends there are, and the scaled pass of a
batch handed to the compiled loop of :mod:`irl._numba` where it applies.

Layouts: as :mod:`irl._numba`'s (the transition operator action-major, ``pi[a, s]``, local
factors ``factor[n, t, a, s]`` or a state part ``state[n, t, s]`` and an action part
``action[n, t, a]``), results as :class:`~irl.inference.PosteriorStats`.
"""

from __future__ import annotations

import numpy as np

from irl._validation import describe
from irl.inference.packing import PosteriorStats, _Emissions
from irl.inference.scaled import _scaled_floor
from irl.observation.base import finite_min

#: Kernels of the scaled pass: numpy and scipy (the default and the reference), or the
#: compiled loop of :mod:`irl._numba` (``pip install onionsort[fast]``).
BACKENDS = ("numpy", "numba")

#: Largest state parts (``N T S`` floats) the numba backend computes for a whole batch (1 GiB),
#: and largest local factors (``N T S A``) it computes when the model does not factor (256 MB;
#: beyond that the numpy pass, which computes them chunk by chunk, is as fast).
_NUMBA_ELEMENTS = 1 << 27
_NUMBA_FACTOR_ELEMENTS = 1 << 25


def check_backend(backend) -> str:
    """``backend`` if it is one of :data:`BACKENDS` and can run here; else a ValueError
    (TypeError) that names it.

    Parameters
    ----------
    backend : str
        ``"numpy"``, or ``"numba"`` where numba is installed.

    Returns
    -------
    str
        ``backend``.
    """
    if not isinstance(backend, str):
        raise TypeError(f"backend must be one of {BACKENDS}; got {describe(backend)}")
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}; got {backend!r}")
    if backend == "numba":
        from irl import _numba

        if not _numba.available():
            raise ValueError("backend 'numba' needs numba, which is not installed: "
                             "pip install 'onionsort[fast]' (or pip install numba)")
    return backend


def _numba_pass(mdp, log_policy, emissions: _Emissions, shape, lengths, log_p0):
    """The scaled pass as one compiled loop (:mod:`irl._numba`); ``None`` when it does not
    apply (a time-indexed policy, a batch whose local factors are too large to hold) or its
    range check fails. A batch whose factors are not kept goes in as a state part and an action
    part when the model factors that way (``N T S`` floats instead of ``N T S A``), its state
    part as two factors where the model reads the state that way (``N T (S / n + n)``)."""
    from irl import _numba

    n_demos, length = shape
    S, A = mdp.n_states, mdp.n_actions
    F = _scaled_floor(mdp)
    if log_policy.ndim != 2 or F < 20.0:
        return None
    log_pi_min = finite_min(log_policy)
    csr = mdp._action_major_csr
    operator = (csr.indptr, csr.indices, csr.data)
    pi = np.ascontiguousarray(np.exp(log_policy).T)
    tail_args = (np.asarray(lengths, dtype=np.int64), np.exp(log_p0), float(F))
    parts = kron = None
    if emissions.factors is None:  # the state parts as two factors, else whole if they fit
        kron = emissions.kronecker(0, length)
        if kron is None and n_demos * length * S <= _NUMBA_ELEMENTS:
            parts = emissions.separable(0, length)
    if kron is not None:
        head, tail, action, shift, min_log = kron
        if min_log + log_pi_min < -F:
            return None
        ok, ll, occupancy, initial = _numba.scaled_forward_backward_kronecker(
            *operator, pi, head, tail, action, shift, *tail_args)
    elif parts is not None:
        state, action, shift, min_log = parts
        if min_log + log_pi_min < -F:
            return None
        ok, ll, occupancy, initial = _numba.scaled_forward_backward_separable(
            *operator, pi, state, action, shift, *tail_args)
    else:
        if emissions.factors is None and n_demos * length * S * A > _NUMBA_FACTOR_ELEMENTS:
            return None  # the numpy pass computes them chunk by chunk instead
        blk = emissions.steps(0, length)
        if not blk.possible or blk.min_log + log_pi_min < -F:
            return None
        ok, ll, occupancy, initial = _numba.scaled_forward_backward(
            *operator, pi, blk.factor, blk.shift, *tail_args)
    if not ok:
        return None
    return PosteriorStats(log_likelihood=ll, occupancy=occupancy, initial=initial)
