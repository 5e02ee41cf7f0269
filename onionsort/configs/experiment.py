"""The config of stage ``experiment`` (:mod:`onionsort.stages.experiment`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

from onionsort.configs import common, documented, option
from onionsort.configs.parallel import ParallelOptions

__all__ = ["DOMAINS", "PAPER_POINTS", "QUICK_POINTS", "ExperimentConfig"]

#: The paper's sweeps: (occlusion, noise) points per domain.
PAPER_POINTS = {
    # Fig. 1b: occlusion 10-40% at noise 0 and 30%; Fig. 1c: noise 20-45% without occlusion.
    "forestworld": [(o, n) for n in (0.0, 0.3) for o in (0.1, 0.2, 0.3, 0.4)]
    + [(0.0, n) for n in (0.2, 0.25, 0.3, 0.35, 0.4, 0.45)],
    # Fig. 3a-b: occlusion at the estimated 30% noise.
    "sorting": [(o, 0.3) for o in (0.0, 0.1, 0.2, 0.3, 0.4)],
}
#: The small sweeps of ``quick``, that take seconds.
QUICK_POINTS = {
    "forestworld": [(0.1, 0.3), (0.3, 0.3), (0.0, 0.2), (0.0, 0.4)],
    "sorting": [(0.1, 0.3), (0.3, 0.3)],
}
#: The sweeps' domains
DOMAINS = tuple(PAPER_POINTS)


@documented
@dataclass(frozen=True)
class ExperimentConfig(ParallelOptions):
    """A sweep as asked for; None fields take the paper's (or the quick) defaults.

    ``occlusion`` and ``noise`` are the grid; both None: the domain's :data:`PAPER_POINTS`
    (:data:`QUICK_POINTS` with ``quick``). ``backend`` is not part of the sweep's identity: a
    sweep may be resumed with the other.
    """

    domain: str = option(positional=True, choices=DOMAINS,
                         help="the paper's domain: forestworld or sorting (onion sorting)")
    occlusion: tuple[float, ...] | None = option(
        None, type=common.floats,
        help="occlusion rates, e.g. 0.1,0.2,0.3 (default: the paper's points; 0 when only "
             "--noise is given)")
    noise: tuple[float, ...] | None = option(
        None, type=common.floats,
        help="observation-noise levels, e.g. 0,0.3 (default: the paper's points; 0.3 when "
             "only --occlusion is given)")
    batches: int | None = option(None, help="batches per point (default: 10; 3 with --quick)")
    #: Demonstrations per batch; several values sweep them.
    trajectories: int | tuple[int, ...] | None = None
    #: Steps per demonstration; several values sweep them.
    length: int | tuple[int, ...] | None = None
    #: Learner settings (``irl.experiments.parse_learner_setting``): betas, factors of the
    #: domain's beta (``x0.5``) or ``paper``; None: the domain's true beta.
    learner_beta: tuple[str, ...] | None = None
    #: Learners of :data:`irl.learners.LEARNERS`; by default the four reward learners (the
    #: behaviour-cloning baselines ``bc`` and ``bc-em`` are asked for by name; a cloned policy
    #: is scored by its own actions).
    methods: tuple[str, ...] = common.IRL_METHODS
    seed: int = common.seed()
    quick: bool = option(False, help="a small sweep that takes seconds")
    backend: str = common.backend()
    out: Path | None = option(None, help="run folder (default: runs/experiment-DOMAIN)")
    resume: bool = option(False, help="continue an interrupted sweep in --out: keep the trials "
                                      "in its results.csv.partial and run the rest (same "
                                      "options; --backend may differ)")
    cli_help: ClassVar[dict[str, str]] = {"pieces": "trials"}

    def __post_init__(self) -> None:
        from irl.inference import check_backend

        check_backend(self.backend)
        if self.executor == "process":  # the former name of the local executor
            object.__setattr__(self, "executor", "local")
        super().__post_init__()
        if self.batches is not None and self.batches < 1:
            raise ValueError(f"batches must be >= 1; got {self.batches}")

    def sweep(self):
        """The :class:`irl.experiments.SweepConfig` this resolves to."""
        from irl.experiments import SweepConfig

        if self.occlusion is not None or self.noise is not None:
            occ = self.occlusion if self.occlusion is not None else (0.0,)
            noise = self.noise if self.noise is not None else (0.3,)
            points = [(o, n) for n in noise for o in occ]
        else:
            points = (QUICK_POINTS if self.quick else PAPER_POINTS)[self.domain]
        defaults = {"batches": 3 if self.quick else 10, "trajectories": 10,
                    "length": 15 if self.domain == "forestworld" else 20}
        return SweepConfig(
            domain=self.domain, points=tuple(points), methods=tuple(self.methods),
            batches=self.batches if self.batches is not None else defaults["batches"],
            trajectories=self.trajectories or defaults["trajectories"],
            length=self.length or defaults["length"],
            learners=tuple(self.learner_beta or ("x1",)), seed=self.seed,
            backend=self.backend)

    @property
    def folder(self) -> Path:
        return self.out or Path("runs") / f"experiment-{self.domain}"
