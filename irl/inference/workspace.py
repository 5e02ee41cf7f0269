"""Scratch arrays of the scaled pass, kept between passes in one thread.

Layout: none (named float arrays of any shape).
"""

from __future__ import annotations

import threading
from contextlib import contextmanager

import numpy as np

#: Largest scratch array (floats) a thread keeps between passes (8 MB).
_WORKSPACE_ELEMENTS = 1 << 20


class _Workspace(threading.local):
    """Scratch arrays of the scaled pass, kept between calls in one thread.

    A fit runs forward-backward on the same shapes a few dozen times; a fresh array comes from
    the operating system as untouched pages, and faulting them in can cost more than the
    arithmetic on them (on a virtual machine, memory freed a few seconds earlier may have been
    handed back to the host, and faulting it in again took about 2 ms per MB on the 2-core VM
    of the figures in docs/performance.md). Every array is kept until the pass ends, so that a
    pass asks for each of its arrays once; then those above ``_WORKSPACE_ELEMENTS`` floats are
    dropped, unless the caller holds them for its next passes (:func:`scratch_held`).
    """

    def __init__(self) -> None:
        self.arrays: dict[str, np.ndarray] = {}
        self.holders = 0

    def get(self, name: str, shape: tuple[int, ...]) -> np.ndarray:
        """An uninitialized float array of ``shape``, reused when the last one fits."""
        a = self.arrays.get(name)
        if a is None or a.shape != shape:
            a = self.arrays[name] = np.empty(shape)
        return a

    def release(self) -> None:
        """Drop the arrays above ``_WORKSPACE_ELEMENTS`` floats, unless they are held."""
        if self.holders:
            return
        for name in [k for k, a in self.arrays.items() if a.size > _WORKSPACE_ELEMENTS]:
            del self.arrays[name]


_workspace = _Workspace()


@contextmanager
def scratch_held():
    """Keep the scaled pass's large scratch arrays between the passes run inside (in this
    thread), and drop them at the end.

    A fit runs forward-backward once per gradient on the same shapes; at S = 100,000 its
    predicted marginals alone are 800 MB, faulted in afresh by every pass unless held. The
    learners hold them for the length of a fit; a single pass drops them when it ends.

    Yields
    ------
    None
        A context manager: ``with scratch_held(): ...``.
    """
    _workspace.holders += 1
    try:
        yield
    finally:
        _workspace.holders -= 1
        _workspace.release()
