"""One executor for every stage whose pieces are independent: local worker processes or Ray.

A stage cuts its work into pieces (sessions to record or perceive, line-ups to evaluate,
methods to learn, repeats of a demo, trials of a sweep), each a picklable value and a
module-level function of it, and hands them to :func:`run_pieces` with the stage config's
:class:`ParallelOptions`:

- ``executor="local"``: ``workers`` processes on this machine (forked from this process while
  it holds no library with threads of its own, else a ``forkserver`` pool: each worker starts
  clean, whatever threads this process runs, and loads what its pieces need;
  the pool is kept for the next pieces, of this stage or the next, while this process runs);
  ``workers=1`` runs the pieces here, one after another, with no pool at all.
- ``executor="ray"``: Ray tasks of one CPU each, on the Ray instance this process has joined,
  else on ``ray_address`` (or ``RAY_ADDRESS``): an existing cluster; else on a new local
  instance of ``workers`` CPUs.

What a piece computes depends only on the piece (its seed comes from what it is: a session's
index, a repeat, a method), never on which worker ran it or when, so every executor and every
worker count give the same results. Each worker runs torch, OpenMP and BLAS on one thread
(:func:`worker_threads`), so that N workers do not oversubscribe N cores, and keeps what it
loads (the perception models, :func:`onionsort.stages.models.PerceptionModels.load_cached`)
for all the pieces it runs.

One progress bar counts the pieces. Ctrl-C, or SIGTERM where the stage turns it into one,
stops the workers' pieces too (a worker takes SIGTERM as Ctrl-C). A piece that fails stops the
run with one line naming it (a ``ValueError`` where the piece said its input was bad, else a
``RuntimeError``); a worker that dies (killed, out of memory) does the same, naming the pieces
it may have been running.
Nothing is dropped silently: ``--resume``, where a stage has it, finishes the run.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from typing import TypeVar

from onionsort.configs.parallel import EXECUTORS, TORCH_THREADS, ParallelOptions

__all__ = [
    "EXECUTORS",
    "RAY_EXTRA",
    "TORCH_THREADS",
    "ParallelOptions",
    "RayExecutor",
    "WorkerLost",
    "run_pieces",
    "torch_threads",
    "worker_threads",
]

#: How to install Ray (an optional extra).
RAY_EXTRA = 'pip install -e ".[ray]"'
#: Threads of torch, OpenMP and BLAS in this process: 1 in a worker, else the library default.
_WORKER_THREADS: int | None = None
_THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")

logger = logging.getLogger(__name__)

P = TypeVar("P")
R = TypeVar("R")


def worker_threads() -> int | None:
    """Threads a library may use in this process: 1 in a worker of :func:`run_pieces`, else
    None (its own default)."""
    return _WORKER_THREADS


def torch_threads(default: int = TORCH_THREADS) -> int:
    """Threads a stage runs torch on: 1 in a worker of :func:`run_pieces`, else ``default``.

    A pool has at most as many workers as the machine has cores (or fewer, with fewer pieces,
    or where each piece would use more than one core:
    :func:`~onionsort.configs.parallel.default_workers`), so one
    thread each keeps them from oversubscribing the cores: two torch pools of two threads each
    on two cores wait on each other's spinning threads and run several times slower."""
    return worker_threads() or default


#: In a local worker: the pool's table of which process runs which piece (a slot per worker,
#: see :func:`_tracked`), shared with the parent, which reads it when a worker dies.
_RUNNING = None


def _start_worker(running=None, parent: int | None = None) -> None:
    """A worker's initializer: one thread for torch, OpenMP and BLAS (set before any of them
    loads, a local worker being a fresh process), the pool's table of running pieces, and a
    watch on the ``parent`` process: a local worker whose command died (killed, or ended
    without shutting its pool) stops its piece as on Ctrl-C instead of writing on alone."""
    global _WORKER_THREADS, _RUNNING
    _WORKER_THREADS = 1
    _RUNNING = running
    for name in _THREAD_VARIABLES:  # for libraries not loaded yet
        os.environ[name] = "1"
    if "torch" in sys.modules:  # loaded already (a Ray worker that ran torch before)
        sys.modules["torch"].set_num_threads(1)
    with contextlib.suppress(ImportError):  # BLAS and OpenMP pools loaded already
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)
    if running is not None:  # a local worker stops its piece on SIGTERM as on Ctrl-C
        signal.signal(signal.SIGTERM, _interrupt)
    if parent is not None:
        threading.Thread(target=_watch_parent, args=(parent,), daemon=True,
                         name="watch-parent").start()


def _watch_parent(pid: int, every: float = 1.0, grace: float = 10.0) -> None:
    """Once process ``pid`` is gone (polled every ``every`` s), stop this worker: SIGTERM
    first, which ends its piece as Ctrl-C does (files finished, partial names removed), then,
    ``grace`` s later, exit (the pool's loop would wait for work from no one)."""
    while True:
        time.sleep(every)
        try:
            os.kill(pid, 0)
        except (ProcessLookupError, PermissionError):  # gone, or its number reused
            break
    os.kill(os.getpid(), signal.SIGTERM)
    time.sleep(grace)
    os._exit(1)


def _interrupt(signum, _frame):
    raise KeyboardInterrupt(f"signal {signum}")


def _tracked(fn: Callable[[P], R], index: int, piece: P) -> R:
    """Run ``fn(piece)`` in a local worker, marked in the pool's table (a slot per worker:
    its pid, and the piece it runs plus one, 0 when idle)."""
    pid = os.getpid()
    with _RUNNING.get_lock():
        slots = range(0, len(_RUNNING), 2)
        slot = next((k for k in slots if _RUNNING[k] == pid), None)
        if slot is None:
            slot = next(k for k in slots if _RUNNING[k] == 0)
        _RUNNING[slot], _RUNNING[slot + 1] = pid, index + 1
    try:
        return fn(piece)
    finally:
        _RUNNING[slot + 1] = 0


def _in_worker(fn: Callable[[P], R], piece: P) -> R:
    """Run ``fn(piece)`` in a Ray worker, capped to one thread like a local one."""
    _start_worker()
    return fn(piece)


class RayExecutor(Executor):
    """Ray tasks behind :class:`concurrent.futures.Executor`'s ``submit``: one CPU per task.

    Joins the Ray instance this process is already connected to if there is one (and leaves
    it running), else ``address`` (None: ``RAY_ADDRESS``, else a new local instance of
    ``num_cpus`` CPUs), which :meth:`shutdown` disconnects from.
    """

    def __init__(self, address: str | None, num_cpus: int) -> None:
        try:
            import ray
        except ImportError:
            raise ValueError(f"--executor ray needs Ray, an optional extra: {RAY_EXTRA}") from None
        self._ray = ray
        self._joined = not ray.is_initialized()
        if self._joined:
            local = address is None and not os.environ.get("RAY_ADDRESS")
            options = {"num_cpus": max(num_cpus, 1), "include_dashboard": False} if local else {}
            ray.init(address=address, logging_level=logging.WARNING, **options)
        self._tasks: dict = {}
        self._refs: list = []

    def submit(self, fn, /, *args, **kwargs) -> Future:
        task = self._tasks.get(fn)
        if task is None:
            task = self._tasks[fn] = self._ray.remote(num_cpus=1)(fn)
        ref = task.remote(*args, **kwargs)
        self._refs.append(ref)
        return ref.future()

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        ray, refs, self._refs = self._ray, self._refs, []
        if refs:
            _, running = ray.wait(refs, num_returns=len(refs), timeout=0)
            for ref in running:
                ray.cancel(ref)
        if self._joined:
            ray.shutdown()
            self._joined = False


class WorkerLost(RuntimeError):
    """A worker process died (killed, out of memory) while it ran a piece: not the input's
    fault nor a bug; running again (``--resume``) finishes the work."""


def _failure(name: str, exc: BaseException) -> Exception:
    """The one-line error of a failed piece: a ValueError where the piece refused its input
    (the CLI's exit 2), else a RuntimeError."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    if isinstance(exc, ValueError | OSError | TypeError | KeyError):
        return ValueError(f"{name}: {text}")
    kind = type(exc).__name__
    return RuntimeError(f"{name} failed ({kind}: {text})" if kind not in text
                        else f"{name} failed ({text})")


def _executor(options: ParallelOptions, n_pieces: int):
    """``(executor, table of running pieces)``: None for this process, a local pool (with its
    table), or Ray."""
    workers = min(options.n_workers, n_pieces)
    if options.executor == "ray":
        return RayExecutor(options.ray_address, options.n_workers), None
    if workers <= 1:
        return None, None
    if workers in _POOLS and _POOL_DIRS.get(workers) != os.getcwd():
        # its workers resolve relative paths against the folder they started in: a kept pool
        # serves only callers in that folder
        _drop(_POOLS[workers][0])
    if workers not in _POOLS:
        method = _start_method()
        logger.info("a local pool of %d workers (%s)", workers, method)
        context = multiprocessing.get_context(method)
        running = context.Array("q", 2 * workers)
        _POOLS[workers] = (ProcessPoolExecutor(max_workers=workers, mp_context=context,
                                               initializer=_start_worker,
                                               initargs=(running, os.getpid())), running)
        _POOL_DIRS[workers] = os.getcwd()
    return _POOLS[workers]


#: Libraries that run thread pools of their own once loaded (Rerun's, Ray's, torch's, OpenCV's):
#: a child forked from a process that holds them can deadlock on a lock one of them held.
_THREADED = ("torch", "rerun", "ray", "cv2")


def _start_method() -> str:
    """How a local pool starts its workers: ``fork`` on Linux while this process has loaded
    none of :data:`_THREADED` (the workers then start at once, with this process's imports:
    a pool forks all its workers when it starts, and never again), else ``forkserver`` (each
    worker starts clean and imports what its pieces need), or ``spawn`` on Windows."""
    if sys.platform == "win32":
        return "spawn"
    if sys.platform == "linux" and not any(name in sys.modules for name in _THREADED):
        return "fork"
    return "forkserver"


#: Local pools, by worker count, kept while this process runs: the next pieces (of this
#: stage, or of the next one, as in a demo) run on workers that have imported and loaded what
#: they need already. A pool is dropped after a failure or an interruption.
_POOLS: dict[int, tuple[ProcessPoolExecutor, object]] = {}
#: The working folder each kept pool's workers started in (and so resolve relative paths in).
_POOL_DIRS: dict[int, str] = {}


def _drop(executor: Executor) -> None:
    """Shut ``executor`` down, and forget it if it is a kept local pool."""
    for workers, (pool, _) in list(_POOLS.items()):
        if pool is executor:
            del _POOLS[workers]
            _POOL_DIRS.pop(workers, None)
    executor.shutdown(wait=True, cancel_futures=True)


def run_pieces(fn: Callable[[P], R], pieces: Sequence[P], options: ParallelOptions, *,
               names: Sequence[str], desc: str, unit: str = "piece",
               progress: bool = True) -> Iterator[tuple[int, R]]:
    """Run ``fn(piece)`` for every piece; yield ``(index, result)`` as each finishes.

    Parameters
    ----------
    fn : callable
        A module-level function (workers import it by name).
    pieces : sequence
        Picklable values, one per piece.
    options : ParallelOptions
        Where to run them.
    names : sequence of str
        What each piece is (``session_003.mcap``, ``repeat 2, mmap-birl``), for messages.
    desc, unit : str
        The progress bar's label and unit.
    progress : bool
        Show the progress bar.

    Raises
    ------
    ValueError or RuntimeError
        The first piece that fails, or the pieces a dead worker may have held, by name; the
        pieces not started yet are cancelled.
    """
    from tqdm import tqdm

    pieces = list(pieces)
    if len(names) != len(pieces):
        raise ValueError(f"names must name each of the {len(pieces)} pieces; got "
                         f"{len(names)}")
    with tqdm(total=len(pieces), desc=desc, unit=unit, disable=not progress) as bar:
        executor, running = _executor(options, len(pieces)) if pieces else (None, None)
        if executor is None:
            for i, piece in enumerate(pieces):
                try:
                    result = fn(piece)
                except Exception as exc:
                    raise _failure(names[i], exc) from exc
                bar.update()
                yield i, result
            return
        futures: dict[Future, int] = {}
        whole = False
        try:
            for i, piece in enumerate(pieces):
                future = (executor.submit(_tracked, fn, i, piece) if running is not None
                          else executor.submit(_in_worker, fn, piece))
                futures[future] = i
            for future in as_completed(futures):
                i = futures[future]
                try:
                    result = future.result()
                except BrokenProcessPool:
                    held = [names[running[k + 1] - 1] for k in range(0, len(running), 2)
                            if 0 < running[k + 1] <= len(pieces)] or [names[i]]
                    raise WorkerLost(
                        f"a worker process died (killed, or out of memory) running "
                        f"{' or '.join(held)}; run again (with --resume where the command has "
                        "it) to finish") from None
                except Exception as exc:
                    cause = _ray_cause(exc)
                    if isinstance(cause, WorkerLost):
                        raise WorkerLost(f"{names[i]}: {cause}") from None
                    raise _failure(names[i], cause) from exc
                bar.update()
                yield i, result
            whole = True
        except KeyboardInterrupt:  # Ctrl-C or SIGTERM here: the workers stop their pieces too
            for process in getattr(executor, "_processes", {}).values():
                with contextlib.suppress(OSError):
                    process.terminate()
            raise
        finally:
            for future in futures:
                future.cancel()
            if not (whole and running is not None):  # a kept local pool stays, whole
                _drop(executor)


def _ray_cause(exc: BaseException) -> BaseException:
    """The piece's own exception inside Ray's wrapper (``RayTaskError``), where there is one."""
    cause = getattr(exc, "cause", None)
    if isinstance(cause, BaseException):
        return cause
    if type(exc).__name__ in ("WorkerCrashedError", "NodeDiedError"):
        return WorkerLost("its Ray worker died (killed, or out of memory); run again (with "
                          "--resume where the command has it) to finish")
    return exc
