"""The config of stage ``evaluate`` (:mod:`onionsort.stages.evaluate`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from onionsort.configs import common, option

__all__ = ["POLICIES", "EvaluateConfig"]

#: Whose policy the Sawyer executes: a learning run's, or the task's true (expert) policy.
POLICIES = ("learned", "expert")


@dataclass(frozen=True)
class EvaluateConfig:
    """Which policy to evaluate, on how many onions, inspected how.

    Attributes
    ----------
    run : Path or None
        A folder written by ``learn`` (the ``learned`` policy); None with ``policy="expert"``.
    onions, blemished : int
        Onions on the line, and how many of them are blemished.
    seed : int
    models : Path or None
        Perception models folder (None: the shipped models).
    ground_truth_inspection : bool
        Perfect inspection instead of the detector (for comparison).
    rerun : bool
        Write ``evaluation.rrd``.
    mcap : bool
        Write ``evaluation.mcap``, the run as a session (Foxglove, ``rerun mcap convert``,
        :func:`recordings.open_session`).
    difficulty : str
        Perception difficulty, a level of ``robot.difficulty.DIFFICULTY_LEVELS`` (``clean``:
        today's station).
    connect : str or None
        Also stream the Rerun recording to a viewer at this gRPC URL
        (``rerun+http://HOST:PORT/proxy``).
    policy : {"learned", "expert"}
        The learning run's greedy policy, or the task's true one (no run needed: measures the
        robot's perception alone).
    out : Path or None
        Folder for the outputs (None: ``run``; required with ``policy="expert"``).
    inspection_views : int
        Views the Sawyer takes of every onion (:func:`robot.station.inspection_poses`), at most:
        it stops showing an onion once its call is settled (no further view could change it).
    every_view : bool
        Take all ``inspection_views`` views of every onion, settled or not: each onion's call is
        the one its settled views gave, but the views after draw their image noise otherwise.
    miss_cost, waste_cost : float or None
        Cost of a blemished onion left on the line, and of a good onion binned (None: the
        task's, from its reward); the robot bins from ``P(blemished) >= waste / (waste +
        miss)``.
    fusion : str or None
        How views are fused (:data:`perception.fusion.FUSION_RULES`; None: the inspection
        classifier's own rule).
    device : str
        Where torch runs the models: ``auto`` (CUDA when present), ``cpu`` or ``cuda``.
    defer_below : float or None
        Defer to a person where the robot is less sure than this that its next action is right
        (:func:`robot.evaluation.confidence_in`: the confidence of ``policy_confidence.json``,
        from ``onionsort learn --posterior``, weighed over what an inspected onion may be): the
        onion goes to a check tray and is counted apart. None never defers.
    """

    run: Path | None = None  # the command's option takes several (commands/evaluate.py)
    policy: str = option("learned", choices=POLICIES,
                         help="the run's learned policy (default), or the task's own: the "
                              "robot's perception measured apart from learning")
    out: Path | None = option(None, help="folder for the outputs (default: RUN_DIR; needed with "
                                         "--policy expert)")
    onions: int = option(50, help="onions on the line (50)")
    blemished: int = option(30, help="how many are blemished (30)")
    seed: int = common.seed(help=None)
    models: Path | None = common.models()
    ground_truth_inspection: bool = option(False, help="perfect inspection instead of the "
                                                       "detector (for comparison)")
    rerun: bool = option(True, help="skip the Rerun recording")
    mcap: bool = option(True, help="skip the session MCAP of the run (evaluation.mcap)")
    connect: str | None = common.connect("the Sawyer's run (evaluation.rrd)")
    difficulty: str = common.difficulty()
    inspection_views: int | None = common.inspection_views()
    miss_cost: float | None = common.miss_cost()
    waste_cost: float | None = common.waste_cost()
    fusion: str | None = common.fusion()
    every_view: bool = option(False, help="take every inspection view of every onion, even once "
                                          "its call is settled (each onion's call is what its "
                                          "first views settled; later onions see the image "
                                          "noise drawn otherwise)")
    defer_below: float | None = common.defer_below("a RUN_DIR of `onionsort learn --posterior`")
    device: str = common.device()

    def __post_init__(self) -> None:
        from perception.fusion import FUSION_RULES
        from robot.inspection_poses import INSPECTION_VIEWS

        common.check_difficulty(self.difficulty)
        common.check_device(self.device)
        if self.policy not in POLICIES:
            raise ValueError(f"policy must be one of {', '.join(POLICIES)}; got "
                             f"{self.policy!r}")
        if self.policy == "learned" and self.run is None:
            raise ValueError("a learned policy needs its run folder (RUN_DIR of `onionsort "
                             "learn`); or evaluate the task's own with --policy expert")
        if self.policy == "expert" and self.out is None and self.run is None:
            raise ValueError("--policy expert needs --out DIR, the folder for its results")
        if self.inspection_views is None:
            object.__setattr__(self, "inspection_views", INSPECTION_VIEWS)
        if isinstance(self.inspection_views, bool) or self.inspection_views < 1:
            raise ValueError(f"inspection_views must be >= 1; got {self.inspection_views}")
        for name in ("miss_cost", "waste_cost"):
            value = getattr(self, name)
            if value is not None and not value >= 0:
                raise ValueError(f"{name} must be >= 0; got {value}")
        if self.miss_cost == 0 and self.waste_cost == 0:
            raise ValueError("miss_cost and waste_cost cannot both be 0")
        if self.fusion is not None and self.fusion not in FUSION_RULES:
            raise ValueError(f"fusion must be one of {', '.join(FUSION_RULES)}; got "
                             f"{self.fusion!r}")
        if self.connect is not None:
            from recordings.rerun.common import check_viewer_url

            check_viewer_url(self.connect)
        if self.defer_below is not None:
            if isinstance(self.defer_below, bool) or not 0.0 < self.defer_below <= 1.0:
                raise ValueError(f"defer_below must be in (0, 1]; got {self.defer_below!r}")
            if self.policy == "expert":
                raise ValueError("--defer-below reads a learned policy's confidence; the expert "
                                 "policy has none (evaluate a RUN_DIR of `onionsort learn "
                                 "--posterior`)")
        if self.onions < 1:
            raise ValueError(f"onions must be >= 1; got {self.onions}")
        if not 0 <= self.blemished <= self.onions:
            raise ValueError(f"blemished must be in [0, onions={self.onions}]; got "
                             f"{self.blemished}")

    @property
    def folder(self) -> Path:
        """Where the outputs go: ``out``, else the run folder."""
        return Path(self.out if self.out is not None else self.run)

    @property
    def threshold(self) -> float:
        """The fused probability of a blemish from which the robot bins an onion."""
        return common.sorting_threshold(self.miss_cost, self.waste_cost)
