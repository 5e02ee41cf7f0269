"""``onionsort learn``: learn the sorter's reward from perceived sessions (an offline run).

``--method bc`` or ``bc-em`` clones the sorter's policy instead (behaviour cloning, at face
value or through the observation model): no reward is learned.

The learner sees only the perceived observations (``onionsort perceive``), never ground truth,
through the observation model of ``onionsort calibrate``. Sessions perceived by other models, or
in another depth mode, than the calibration measured are refused (``--allow-model-mismatch``).
Writes ``model.json``, ``learning_curve.json``/``.png`` and ``learn.rrd`` into ``--out``;
``--connect URL`` also streams the Rerun recording to a viewer on another machine.

Examples
--------
    onionsort learn runs/rec/*.mcap --method mmap-birl \\
        --observation-model runs/calibration/calibration.json --out runs/learn-mmap
    onionsort learn runs/rec/*.mcap --observation-model runs/calibration/calibration.json \\
        --out runs/learn-mmap --connect rerun+http://192.168.1.20:9876/proxy
    onionsort learn runs/rec/*.mcap --observation-model runs/calibration/calibration.json \\
        --out runs/learn-mmap --backend numba       # compiled forward-backward (the fast extra)
    onionsort learn runs/rec/*.mcap --observation-model runs/calibration/calibration.json \\
        --out runs/learn-mmap --posterior            # + posterior.npz, policy_confidence.json
    onionsort learn runs/rec/*.mcap --observation-model runs/calibration/calibration.json \\
        --method mmap-birl,map-birl,hidden-data-em --out runs/learn   # runs/learn/<method>,
        # the methods in parallel (--workers, --executor ray)
    onionsort learn runs/rec/*.mcap --observation-model runs/calibration/calibration.json \\
        --method bc-em --out runs/learn-bc-em        # behaviour cloning, no reward
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from onionsort.commands import add_command
from onionsort.configs import config_from_args, option
from onionsort.configs.common import METHODS, methods_list
from onionsort.configs.learn import SWAP_METHOD, LearnConfig
from onionsort.configs.parallel import ParallelOptions


@dataclass(frozen=True, kw_only=True)
class LearnCommand(LearnConfig, ParallelOptions):
    """The command's options: the stage's, with several learners at once and where they run."""

    method: tuple[str, ...] = option(("mmap-birl",), type=methods_list(METHODS),
                                     metavar="METHOD[,METHOD...]",
                                     help=f"the learner ({', '.join(METHODS)}); several, "
                                          "comma-separated, learn in parallel, each into "
                                          "OUT/METHOD")
    cli_help: ClassVar[dict[str, str]] = {"pieces": "methods"}


def register(subparsers) -> None:
    add_command(subparsers, "learn", __doc__,
                "learn the sorter's reward from perceived sessions (offline run)",
                LearnCommand, run)


def run(args) -> int:
    from onionsort.stages import learn
    from onionsort.stages.learn import learn_methods

    methods = args.method
    # the swaps concern MMAP-BIRL alone; learn_methods gives them to it and to no other
    first = SWAP_METHOD if args.session_swaps and SWAP_METHOD in methods else methods[0]
    config = config_from_args(LearnConfig, args, method=first)
    if len(methods) == 1:
        models = {methods[0]: learn(config)}
        folders = {methods[0]: args.out}
    else:  # learn_methods checks every method's config before any piece starts
        models = learn_methods(config, methods, config_from_args(ParallelOptions, args))
        folders = {m: args.out / m for m in methods}
    for method, model in models.items():
        print(f"{method}: learned from {len(args.sessions)} session(s) ({model['n_steps']} "
              f"steps, {model['n_occluded']} occluded)")
        if model["theta"] is None:  # behaviour cloning
            print(f"  no reward (behaviour cloning): the policy copies the actions; "
                  f"{len(model['unseen_states'])} state(s) never seen")
        else:
            print("  theta: " + ", ".join(f"{k} {v:+.2f}" for k, v in model["theta"].items()))
        if "session_swaps" in model:
            print(f"  sessions read with the onion's class backwards (prior "
                  f"{model['session_swaps']['rate']:.3f}), posterior probability: "
                  + ", ".join(f"{p:.3f}" for p in model["session_swaps"]["p_swapped"]))
        if "posterior" in model:
            risk = model["posterior"]["risk"]
            print(f"  posterior ({args.posterior_method}, {model['posterior']['n_samples']} "
                  f"samples): P(the policy is optimal) {risk['p_map_optimal']:.3f}, expected "
                  f"ILE {risk['expected_ile']:.3f}")
            print(f"wrote {folders[method] / 'policy_confidence.json'}")
        print(f"wrote {folders[method] / 'model.json'}")
    return 0
