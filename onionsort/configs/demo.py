"""The config of stage ``demo`` (:mod:`onionsort.stages.demo`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

from onionsort.configs import common, documented, option
from onionsort.configs.evaluate import EvaluateConfig
from onionsort.configs.parallel import ParallelOptions

__all__ = ["METHODS", "DemoConfig"]

#: The methods of the demo, in the order its table and the report list them.
METHODS = ("mmap-birl", "map-birl", "hidden-data-em")


@documented
@dataclass(frozen=True)
class DemoConfig(ParallelOptions):
    """The demo's run folder, seed, size, repeats, perception difficulty and models.

    With ``repeats`` above 1 each repeat gets its own folder ``repeat_K``. The recorded
    sessions, the held-out frames the calibration is measured on, and the robot's inspection
    at evaluation all face ``difficulty``. A demo may be resumed with the other ``backend``
    (each repeat's result names the backend its model was learned with, ``backends`` all).
    ``inspection_views``, ``miss_cost``, ``waste_cost``, ``fusion`` and ``defer_below`` are
    :class:`~onionsort.configs.evaluate.EvaluateConfig`'s, ``session_swaps``
    :class:`~onionsort.configs.learn.LearnConfig`'s; with ``defer_below``, both sortings are
    reported. The pieces are the held-out frames' rendering, the repeats' recordings, and
    then every (repeat, method)'s learning and sorting; with fewer repeats than workers the
    recording and perception of a repeat run their sessions in parallel instead.
    """

    seed: int = common.seed()
    out: Path = option(Path("runs/demo"), help="run folder")
    quick: bool = option(False, help="a small, fast run (smoke test)")
    sessions: int | None = option(None, help="sessions recorded per repeat (default: 12; 4 with "
                                                "--quick)")
    difficulty: str = common.difficulty("how hard the world makes perception")
    methods: tuple[str, ...] = option(METHODS, type=common.methods_list(common.METHODS),
                                      metavar="METHOD[,METHOD...]",
                                      help="the learners whose policies the Sawyer sorts with ("
                                           + ", ".join(common.METHODS) + ")")
    repeats: int = option(1, help="repeat with seeds SEED..SEED+K-1 and report 95%% "
                                  "intervals")
    models: Path | None = common.models()
    resume: bool = option(False, help="continue the interrupted demo in --out: skip its "
                                      "finished stages")
    connect: str | None = common.connect("the recordings of record, learn and evaluate")
    backend: str = common.backend()
    inspection_views: int | None = common.inspection_views()
    miss_cost: float | None = common.miss_cost()
    waste_cost: float | None = common.waste_cost()
    fusion: str | None = common.fusion()
    device: str = common.device()
    defer_below: float | None = common.defer_below(
        "MMAP-BIRL and MAP-BIRL then also learn the posterior, and sort the same line-up once "
        "more deferring")
    posterior_method: str = common.posterior_method()
    session_swaps: bool = common.session_swaps()
    cli_help: ClassVar[dict[str, str]] = {"pieces": "repeats' recordings and methods"}

    def __post_init__(self) -> None:
        from irl.experiments import METHODS as LEARNERS
        from irl.inference import check_backend
        from irl.posterior import METHODS as POSTERIOR_METHODS

        super().__post_init__()
        methods = (self.methods,) if isinstance(self.methods, str) else tuple(self.methods)
        if not methods:
            raise ValueError("methods must name at least one learner; got none")
        unknown = [m for m in methods if m not in LEARNERS]
        if unknown:
            raise ValueError(f"methods must be among {LEARNERS}; got {', '.join(unknown)}")
        object.__setattr__(self, "methods", tuple(dict.fromkeys(methods)))
        check_backend(self.backend)
        # the robot's inspection, checked as evaluate checks it (before any work starts)
        checked = EvaluateConfig(policy="expert", out=self.out,
                                 inspection_views=self.inspection_views,
                                 miss_cost=self.miss_cost, waste_cost=self.waste_cost,
                                 fusion=self.fusion, device=self.device)
        if self.defer_below is not None:
            EvaluateConfig(run=self.out, defer_below=self.defer_below)  # checks the value
        if self.posterior_method not in POSTERIOR_METHODS:
            raise ValueError(f"posterior_method must be one of {POSTERIOR_METHODS}; got "
                             f"{self.posterior_method!r}")
        object.__setattr__(self, "inspection_views", checked.inspection_views)
        if self.repeats < 1:
            raise ValueError(f"repeats must be >= 1; got {self.repeats}")
        if self.sessions is not None and self.sessions < 1:
            raise ValueError(f"sessions must be >= 1; got {self.sessions}")
        common.check_difficulty(self.difficulty)
        if self.connect is not None:
            from recordings.rerun.common import check_viewer_url

            check_viewer_url(self.connect)
