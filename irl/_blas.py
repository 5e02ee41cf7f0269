"""One BLAS thread for irl's large array passes.

OpenBLAS hands a dot product of more than 10,000 numbers, and a matrix-vector product above a
similar size, to its thread pool (one thread per core by default). The products irl makes on
large MDPs are bound by memory, so more threads gain little even on idle cores, and on a
machine whose cores are busy the pool's threads spin waiting for each other: on our 2-core
machine beside other jobs, one cold MMAP-BIRL gradient at 102,400 states took 8.98 s of CPU
time with the default pool against 4.35 s on one thread (numba backend: 2.93 s against 1.42
s), while at 10,000 states, under OpenBLAS's threshold, the two were the same
(docs/notes/2026-11-26-irl-cost-in-states.md). That threshold made the cost grow faster than
the state count (x29 for x10.24 the states, against x14 on one thread).

:func:`one_blas_thread` limits BLAS to one thread for the length of a block whose arrays are
large enough for OpenBLAS to thread them; below, it does nothing, since a limiting block
costs about 12 microseconds (the last line of ``python bench/bench_irl.py``'s section [4]).
Layout: none (a context manager).
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator

#: Arrays of at least this many numbers get one BLAS thread: OpenBLAS threads a dot product
#: above 10,000 numbers.
MIN_ELEMENTS = 10_000

_lock = threading.RLock()
_controller = None
#: The limit in force (threadpoolctl's limiter, which restores the pool) and how many blocks,
#: in every thread, are inside it. The limit is the process's, so the first block to enter
#: sets it and the last to leave restores it: a block that restored the pool as it left while
#: another thread's was inside would hand that one the pool, and the other's exit would then
#: restore the one thread it had found, for good.
_limiter = None
_n_inside = 0
#: Whether this thread is inside a limiting block already (a nested block sets nothing).
_inside = threading.local()


def _blas_controller():
    """The process's BLAS libraries (found once: irl has loaded numpy's and scipy's)."""
    global _controller
    with _lock:
        if _controller is None:
            from threadpoolctl import ThreadpoolController

            _controller = ThreadpoolController().select(user_api="blas")
        return _controller


def _set_pool(change) -> None:
    """``change()`` the pool's size from this thread: threadpoolctl (3.8 on) lets one thread
    at a time set OpenBLAS's pool, the first that sets it until it is cleared, and ignores
    the others; the thread that enters or leaves last here may be another than the first."""
    clears = {getattr(type(lib), "clear_controlling_thread", None)
              for lib in _blas_controller().lib_controllers} - {None}
    for clear in clears:
        clear(force=True)
    try:
        change()
    finally:
        for clear in clears:
            clear(force=True)


@contextlib.contextmanager
def one_blas_thread(n_elements: int) -> Iterator[None]:
    """BLAS on one thread within the block, where its arrays hold ``n_elements`` numbers or
    more (for example ``S * A`` for an MDP's Q-function); a limit already lower is kept. The
    pool comes back when the last block of any thread leaves, by an exception or not."""
    global _limiter, _n_inside
    if n_elements < MIN_ELEMENTS or getattr(_inside, "active", False):
        yield
        return
    with _lock:
        if _n_inside == 0:
            made = []
            _set_pool(lambda: made.append(_blas_controller().limit(limits=1)))
            _limiter = made[0]
        _n_inside += 1
    _inside.active = True
    try:
        yield
    finally:
        _inside.active = False
        with _lock:
            _n_inside -= 1
            if _n_inside == 0:
                _set_pool(_limiter.restore_original_limits)
                _limiter = None
