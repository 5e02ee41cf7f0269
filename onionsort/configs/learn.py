"""The config of stage ``learn`` (:mod:`onionsort.stages.learn`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from onionsort.configs import common, documented, option

__all__ = ["BAYESIAN_METHODS", "SWAP_METHOD", "LearnConfig"]

#: The learners with an exact posterior to sample.
BAYESIAN_METHODS = ("mmap-birl", "map-birl")
#: The learner that can doubt how a whole session was read (``session_swaps``).
SWAP_METHOD = "mmap-birl"


@documented
@dataclass(frozen=True, kw_only=True)
class LearnConfig:
    """What to learn from (perceived session files), with which learner, into which run folder.

    A mismatch of models allowed by ``allow_model_mismatch`` is logged and noted in
    ``model.json``, as is the ``backend`` (for every method) and, with ``session_swaps``
    (:meth:`state_abstraction.calibration.Calibration.session_swap`), each session's
    posterior probability of having been swapped. ``posterior_method``: see
    :mod:`irl.posterior`. ``beta`` and ``prior_std`` are what the learner assumes of the
    demonstrator and the reward (:func:`irl.domains.onion_sorting.onion_sorting`'s defaults
    are the simulated sorter's); ``model.json`` records both.
    """

    sessions: tuple[Path, ...] = option(positional=True, nargs="+", metavar="SESSION.mcap",
                                        help="perceived sessions (`onionsort perceive`)")
    #: A learner of :data:`irl.experiments.METHODS` (the command's option takes several:
    #: commands/learn.py).
    method: str = "mmap-birl"
    calibration: Path = option(flag="--observation-model", metavar="FILE",
                               help="calibration.json written by `onionsort calibrate`")
    out: Path = option(help="run folder")
    seed: int = common.seed("the learner's seed")
    beta: float = option(1.5, metavar="BETA",
                         help="the demonstrator's rationality: how surely the person takes the "
                              "best action (the Boltzmann policy's beta; only beta times the "
                              "reward is identifiable), as the simulated sorter's")
    prior_std: float = option(3.0, metavar="STD",
                              help="the standard deviation of the Gaussian prior on each reward "
                                   "weight, around 0")
    overwrite: bool = option(False, help="replace an earlier run in --out")
    allow_model_mismatch: bool = option(False, help="learn even if the sessions were perceived "
                                                    "by other models (or in another sensor "
                                                    "mode) than the calibration measured")
    posterior: bool = option(False, help="also sample the posterior over reward weights "
                                         "(mmap-birl, map-birl): posterior.npz, "
                                         "policy_confidence.json and .png")
    samples: int = option(1000, metavar="N", help="posterior samples")
    posterior_method: str = common.posterior_method()
    session_swaps: bool = common.session_swaps()
    backend: str = common.backend()
    connect: str | None = common.connect("the learning run (learn.rrd)")
    #: Write ``learn.rrd``.
    rerun: bool = True

    def __post_init__(self) -> None:
        from irl.experiments import METHODS
        from irl.inference import check_backend
        from irl.posterior import METHODS as POSTERIOR_METHODS

        if self.method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}; got {self.method!r}")
        for name in ("beta", "prior_std"):
            value = getattr(self, name)
            if not math.isfinite(value) or value <= 0:
                raise ValueError(f"{name} must be a finite number > 0; got {value}")
        if self.session_swaps and self.method != SWAP_METHOD:
            raise ValueError(f"session_swaps needs {SWAP_METHOD}, which marginalizes how each "
                             f"session was read; {self.method} does not")
        if self.posterior and self.method not in BAYESIAN_METHODS:
            raise ValueError(f"a posterior needs a Bayesian method ({', '.join(BAYESIAN_METHODS)}"
                             f"); {self.method} gives a point estimate only")
        if isinstance(self.samples, bool) or not isinstance(self.samples, int) \
                or self.samples < 10:
            raise ValueError(f"samples must be an int >= 10; got {self.samples!r}")
        if self.posterior_method not in POSTERIOR_METHODS:
            raise ValueError(f"posterior_method must be one of {POSTERIOR_METHODS}; got "
                             f"{self.posterior_method!r}")
        check_backend(self.backend)
        common.check_session_files(self.sessions)
        if self.connect is not None:
            from recordings.rerun.common import check_viewer_url

            check_viewer_url(self.connect)
