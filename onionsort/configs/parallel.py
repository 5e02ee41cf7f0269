"""Where a stage's independent pieces run: the fields (and options) every parallel stage's
config inherits (:mod:`onionsort.stages.parallel` runs them)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import ClassVar

from onionsort.configs import documented, option

__all__ = ["EXECUTORS", "TORCH_THREADS", "ParallelOptions", "default_workers",
           "machine_cores"]

#: Where the pieces of a stage can run.
EXECUTORS = ("local", "ray")
#: Threads a stage runs torch on in the command (1 in a worker).
TORCH_THREADS = 2


def machine_cores() -> int:
    """The cores this process may run on (its CPU affinity where the system has one)."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except AttributeError:  # no affinity on this system (macOS, Windows)
        return max(os.cpu_count() or 1, 1)


def default_workers(piece_threads: int = 1, cores: int | None = None) -> int:
    """Workers of a stage whose ``workers`` is not given: ``cores // min(piece_threads,
    cores)``, at least 1 (and never more than the pieces:
    :func:`~onionsort.stages.parallel.run_pieces` starts at most one worker per piece).

    A worker runs a piece on one thread (:func:`~onionsort.stages.parallel.worker_threads`);
    in the command it would run on ``piece_threads``. Where one piece already keeps all the
    cores busy (perceiving on two cores: torch's two threads), a second worker only adds its
    start-up (importing torch, loading the models) and makes two processes fight for the
    cores, so the stage runs its pieces in the command, one after another; a stage whose
    pieces run on one thread (recording, rendering, evaluating, learning) gets a worker per
    core. On 16 cores, perceiving gets 8.
    """
    cores = machine_cores() if cores is None else cores
    return max(1, cores // max(1, min(piece_threads, cores)))


@documented
@dataclass(frozen=True, kw_only=True)
class ParallelOptions:
    """Where a stage's independent pieces run; every parallel stage's config has these fields.
    ``workers`` None is :func:`default_workers` for the stage's ``piece_threads``."""

    executor: str = option("local", choices=EXECUTORS, group="parallel",
                           help="run the {pieces} on local worker processes or as Ray tasks "
                                "(pip install -e \".[ray]\")")
    workers: int | None = option(None, metavar="N", group="parallel",
                                 help="{pieces} at a time: local worker processes, or the CPUs "
                                      "of a new local Ray instance (default: one per core, or "
                                      "one per two cores where a piece runs on torch's "
                                      "threads, as in perceive and calibrate; 1: one after "
                                      "another in this process)")
    ray_address: str | None = option(None, metavar="ADDRESS", group="parallel",
                                     help="the Ray cluster to join, e.g. auto or "
                                          "ray://head:10001 (default: $RAY_ADDRESS, else a "
                                          "local Ray instance of --workers CPUs)")
    #: Cores one piece of this stage keeps busy when it runs in the command: 1 for most, the
    #: torch threads it would get there (:func:`~onionsort.stages.parallel.torch_threads`)
    #: for a stage whose pieces are mostly a network's work (perceive, calibrate). The
    #: default ``workers`` follows from it.
    piece_threads: ClassVar[int] = 1
    #: What the pieces are, in the options' help
    cli_help: ClassVar[dict[str, str]] = {"pieces": "pieces"}
    #: A command lists these options after its own
    cli_last: ClassVar[bool] = True

    def __post_init__(self) -> None:
        if self.executor not in EXECUTORS:
            raise ValueError(f"executor must be one of {', '.join(EXECUTORS)}; got "
                             f"{self.executor!r}")
        if self.workers is not None and (isinstance(self.workers, bool)
                                         or not isinstance(self.workers, int)
                                         or self.workers < 1):
            raise ValueError(f"workers must be >= 1; got {self.workers!r}")
        if self.ray_address is not None and self.executor != "ray":
            raise ValueError(f"ray_address is for executor 'ray'; got executor "
                             f"{self.executor!r} with ray_address {self.ray_address!r}")

    @property
    def n_workers(self) -> int:
        """``workers``, or :func:`default_workers` for this stage's
        ``piece_threads``."""
        return self.workers if self.workers is not None else default_workers(self.piece_threads)

    def parallel_options(self) -> ParallelOptions:
        """These fields alone (to hand on to another stage, or to
        :func:`~onionsort.stages.parallel.run_pieces`), with a local pool's default worker
        count resolved for this stage: a stage run inside another (the demo's calibration and
        perceiving) runs on the workers its caller chose."""
        workers = self.n_workers if self.executor == "local" else self.workers
        return ParallelOptions(executor=self.executor, workers=workers,
                               ray_address=self.ray_address)
