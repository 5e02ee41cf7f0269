"""The config of stage ``eval-posterior`` (:mod:`onionsort.stages.eval_posterior`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from onionsort.configs import common, documented, option
from onionsort.configs.experiment import DOMAINS
from onionsort.configs.parallel import ParallelOptions

__all__ = ["LEVELS", "PosteriorEvalConfig"]

#: The credible levels whose action sets are scored.
LEVELS = (0.5, 0.8, 0.9, 0.95)


@documented
@dataclass(frozen=True, kw_only=True)
class PosteriorEvalConfig(ParallelOptions):
    """Synthetic problems on which MMAP-BIRL's posterior is scored against the expert.

    Problem ``i`` draws ``trajectories`` demonstrations of ``length`` steps from the domain at
    ``noise`` and ``occlusion`` with seed ``seed + i``, and samples the posterior with the same
    seed; each problem is a piece.
    """

    domain: str = option(positional=True, choices=DOMAINS, help="the domain: forestworld or "
                                                                "sorting")
    problems: int = option(40, help="synthetic problems (default: 40)")
    method: str = common.posterior_method()
    samples: int = option(1000, help="posterior samples of each problem (default: 1000)")
    noise: float = option(0.45, help="observation noise of the domain (default: 0.45)")
    occlusion: float = option(0.2, help="share of each demonstration's steps occluded "
                                        "(default: 0.2)")
    trajectories: int = option(2, help="demonstrations of each problem (default: 2)")
    length: int = option(10, help="steps of each demonstration (default: 10)")
    seed: int = option(1000, help="problem i draws its demonstrations and samples with seed "
                                  "SEED + i (default: 1000)")
    backend: str = common.backend()
    cli_help: ClassVar[dict[str, str]] = {"pieces": "problems"}

    def __post_init__(self) -> None:
        from irl.inference import check_backend

        check_backend(self.backend)
        super().__post_init__()
        if self.domain not in DOMAINS:
            raise ValueError(f"domain must be one of {DOMAINS}; got {self.domain!r}")
        if self.method not in common.POSTERIOR_METHODS:
            raise ValueError(f"method must be one of {common.POSTERIOR_METHODS}; got "
                             f"{self.method!r}")
        for name in ("problems", "samples", "trajectories", "length"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1; got {getattr(self, name)}")
        if not 0.0 <= self.noise < 1.0:
            raise ValueError(f"noise must be in [0, 1); got {self.noise}")
        if not 0.0 <= self.occlusion < 1.0:
            raise ValueError(f"occlusion must be in [0, 1); got {self.occlusion}")
        if self.seed < 0:
            raise ValueError(f"seed must be >= 0; got {self.seed}")
