"""``onionsort experiment``: the paper's sweeps (Fig. 1b-d, 3a-b) and data-efficiency sweeps.

Examples
--------
    onionsort experiment forestworld --quick --out runs/forestworld-quick
    onionsort experiment forestworld --out runs/forestworld          # the paper's full sweep
    onionsort experiment sorting --occlusion 0.1,0.2,0.3,0.4 --noise 0.3 --out runs/sorting
    onionsort experiment sorting --trajectories 1,2,4,8 --noise 0.3,0.45 --occlusion 0.2 \\
        --batches 20 --out runs/efficiency                 # 95% bootstrap intervals per point
    onionsort experiment sorting --trajectories 1,2,4,8 --noise 0.3,0.45 --occlusion 0.2 \\
        --batches 20 --methods mmap-birl,map-birl,bc,bc-em --out runs/efficiency-bc  # + cloning
    onionsort experiment sorting --trajectories 2,8 --noise 0.3 --occlusion 0.2 \\
        --learner-beta x0.25,x1,x4,paper --batches 20 --out runs/beta   # misspecified beta
    onionsort experiment forestworld --out runs/forestworld --resume   # after an interruption
    onionsort experiment sorting --quick --backend numba               # compiled kernels
    onionsort experiment forestworld --quick --executor ray            # a local Ray instance
    RAY_ADDRESS=head-node:6379 onionsort experiment forestworld --executor ray   # a cluster
"""

from __future__ import annotations

from dataclasses import dataclass

from onionsort.commands import add_command
from onionsort.configs import config_from_args, option
from onionsort.configs.common import IRL_METHODS, METHODS
from onionsort.configs.experiment import ExperimentConfig


@dataclass(frozen=True, kw_only=True)
class ExperimentCommand(ExperimentConfig):
    """The command's options: the stage's, with the lists as text (the stage parses them)."""

    trajectories: str | None = option(None, help="demonstrations per batch, e.g. 1,2,4,8 "
                                                 "(default: 10)")
    length: str | None = option(None, help="steps per demonstration, e.g. 10,20 (default: 15 "
                                           "on forestworld, 20 on sorting)")
    learner_beta: str | None = option(None, help="beta the learners are fitted with: betas, "
                                                 "factors of the true beta (x0.5,x1,x2) or "
                                                 "paper (0.03) (default: the true beta)")
    methods: str = option(",".join(IRL_METHODS),
                          help=f"comma-separated subset of {','.join(METHODS)}; bc and bc-em "
                               "clone the policy, learning no reward")


def register(subparsers) -> None:
    add_command(subparsers, "experiment", __doc__,
                "ILE and run-time sweeps of the paper's figures", ExperimentCommand, run)


def run(args) -> int:
    from onionsort.stages import run_experiment
    from onionsort.stages.experiment import format_table, parse_list

    def listed(name, kind="int"):
        value = getattr(args, name.replace("-", "_"))
        return None if value is None else parse_list(value, name, kind)

    config = config_from_args(
        ExperimentConfig, args, trajectories=listed("trajectories"), length=listed("length"),
        learner_beta=listed("learner-beta", "learner"),
        methods=tuple(m.strip() for m in args.methods.split(",") if m.strip()))
    summary = run_experiment(config)
    print(format_table(summary["points"]))
    print(f"wrote results.csv, summary.json and {len(summary['plots'])} plots to "
          f"{config.folder}")
    print(f"report: {summary['report']}")
    return 0
