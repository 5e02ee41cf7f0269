"""The config of stage ``evaluate`` (:mod:`onionsort.stages.evaluate`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from onionsort.configs import common, documented, option

__all__ = ["POLICIES", "EvaluateConfig"]

#: Whose policy the Sawyer executes: a learning run's, or the task's true (expert) policy.
POLICIES = ("learned", "expert")


@documented
@dataclass(frozen=True)
class EvaluateConfig:
    """Which policy to evaluate, on how many onions, inspected how.

    The Sawyer takes ``inspection_views`` views of an onion at most: it stops showing it once
    its call is settled (no further view could change it). ``mcap`` writes the run as a
    session (Foxglove, ``rerun mcap convert``, :func:`recordings.open_session`).
    ``defer_below`` reads the confidence of the run's ``policy_confidence.json``
    (:func:`robot.cell.confidence_in`); None never defers. With ``lineup`` the recorded
    views stand in for the arm (:mod:`onionsort.stages.lineup`): the line-up's size, seed and
    difficulty are the recording's, and only ``evaluation.json`` and ``tally.csv`` are
    written.
    """

    #: A folder written by ``learn`` (the ``learned`` policy's); None with ``policy="expert"``
    #: (the command's option takes several: commands/evaluate.py).
    run: Path | None = None
    policy: str = option("learned", choices=POLICIES,
                         help="the run's learned policy, or the task's own (expert): the "
                              "robot's perception measured apart from learning")
    out: Path | None = option(None, help="folder for the outputs (default: RUN_DIR; needed with "
                                         "--policy expert)")
    onions: int = option(50, help="onions on the line")
    blemished: int = option(30, help="how many are blemished")
    seed: int = common.seed("the line-up's seed")
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
                                          "its call is settled (the call is the same; the "
                                          "probability is every view's)")
    lineup: Path | None = option(None, metavar="SOURCE",
                                 help="replay the policy on a recorded line-up instead of the "
                                      "simulator: a folder of inspection views with "
                                      "lineups.csv (as `label export` writes inspection/, or "
                                      "--record-lineup); needs --truth (default: none)")
    truth: Path | None = option(None, metavar="FILE.csv",
                                help="the --lineup's onions' classes: lineup, index, class "
                                     "(good or blemished) (default: none)")
    record_lineup: Path | None = option(None, metavar="DIR",
                                        help="record the simulated line-up into DIR for "
                                             "--lineup: every view of every onion (as "
                                             "--every-view), lineups.csv and truth.csv "
                                             "(default: none)")
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
        for name in ("lineup", "truth", "record_lineup"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, Path(value))
        if (self.lineup is None) != (self.truth is None):
            raise ValueError("--lineup SOURCE and --truth FILE.csv go together: the recorded "
                             "views, and each onion's class" if self.lineup is not None else
                             "--truth names the classes of a recorded line-up; give it "
                             "with --lineup SOURCE (a simulated line-up knows its own)")
        if self.lineup is not None and self.record_lineup is not None:
            raise ValueError("--record-lineup records a simulated line-up; --lineup replays a "
                             "recorded one: give one of them")
        if self.lineup is not None and self.connect is not None:
            raise ValueError("--connect streams the simulated run; a --lineup replay has none")
        if self.record_lineup is not None:
            object.__setattr__(self, "every_view", True)
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
