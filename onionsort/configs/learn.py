"""The config of stage ``learn`` (:mod:`onionsort.stages.learn`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from onionsort.configs import common, option

__all__ = ["BAYESIAN_METHODS", "SWAP_METHOD", "LearnConfig"]

#: The learners with an exact posterior to sample.
BAYESIAN_METHODS = ("mmap-birl", "map-birl")
#: The learner that can doubt how a whole session was read (``session_swaps``).
SWAP_METHOD = "mmap-birl"


@dataclass(frozen=True, kw_only=True)
class LearnConfig:
    """What to learn from, with which learner, into which run folder.

    Attributes
    ----------
    sessions : tuple of Path
        Perceived session files.
    calibration : Path
        ``calibration.json`` from ``onionsort calibrate``.
    out : Path
        Run folder.
    method : str
        A learner of :data:`irl.experiments.METHODS`.
    seed : int
    allow_model_mismatch : bool
        Learn even when the sessions were perceived by other models, or in another sensor
        mode, than the calibration was measured with (logged, and noted in ``model.json``).
    rerun : bool
        Write ``learn.rrd``.
    overwrite : bool
        Replace an earlier run's ``model.json`` in ``out``.
    connect : str or None
        Also stream the Rerun recording to the viewer at this gRPC URL
        (``rerun+http://HOST:9876/proxy``), in addition to ``learn.rrd``.
    backend : str
        Forward-backward kernels (``irl.inference.BACKENDS``): ``numpy`` or ``numba`` (the
        ``fast`` extra), equal to rounding; used by the methods that run forward-backward
        (``mmap-birl``, ``bc-em``), recorded in ``model.json`` for every method.
    posterior : bool
        Also sample the posterior over reward weights (``mmap-birl`` and ``map-birl`` only).
    samples : int
        Posterior samples (1000).
    posterior_method : str
        ``mcmc`` (HMC chains, the default) or ``laplace`` (a Gaussian at the MAP, fast); see
        :mod:`irl.posterior`.
    session_swaps : bool
        ``mmap-birl`` only: let each session's reads of the onion's class have been backwards
        as a whole, at the rate the calibration measured on its held-out sessions
        (:meth:`state_abstraction.calibration.Calibration.session_swap`; the learner's
        ``session_swap``). Each session's posterior probability of having been swapped is
        written to ``model.json``.
    """

    sessions: tuple[Path, ...] = option(positional=True, nargs="+", metavar="SESSION.mcap",
                                        help=None)
    method: str = "mmap-birl"  # the command's option takes several (commands/learn.py)
    calibration: Path = option(flag="--observation-model", metavar="FILE",
                               help="calibration.json written by `onionsort calibrate`")
    out: Path = option(help="run folder")
    seed: int = common.seed("the learner's seed (0)")
    overwrite: bool = option(False, help="replace an earlier run in --out")
    allow_model_mismatch: bool = option(False, help="learn even if the sessions were perceived "
                                                    "by other models (or in another sensor "
                                                    "mode) than the calibration measured")
    posterior: bool = option(False, help="also sample the posterior over reward weights "
                                         "(mmap-birl, map-birl): posterior.npz, "
                                         "policy_confidence.json and .png")
    samples: int = option(1000, metavar="N", help="posterior samples (1000)")
    posterior_method: str = common.posterior_method()
    session_swaps: bool = common.session_swaps()
    backend: str = common.backend()
    connect: str | None = common.connect("the learning run (learn.rrd)")
    rerun: bool = True

    def __post_init__(self) -> None:
        from irl.experiments import METHODS
        from irl.inference import check_backend
        from irl.posterior import METHODS as POSTERIOR_METHODS

        if self.method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}; got {self.method!r}")
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
