"""Options that several stages' configs share, declared once each: a field factory per option
(``models: Path | None = models()``), the choices the parser offers, the parsers of
list-valued options, and the checks and meanings that stages and configs share (the torch
device, the difficulty level, the sorting threshold of the two costs).

The choices of the libraries are repeated here so that building the parser (every command
does, at start) imports neither ``irl`` (and scipy), torch, the robot's world nor the stages;
tests check that each tuple is the library's: :data:`irl.inference.BACKENDS`,
:data:`irl.experiments.METHODS`, :data:`robot.difficulty.DIFFICULTY_LEVELS`,
:data:`robot.inspection_poses.INSPECTION_VIEWS`, :data:`perception.fusion.FUSION_RULES`,
:data:`perception.fusion.CALIBRATION_FORMS`,
:data:`onionsort.stages.inspection.INSPECTION_CAMERAS`,
:data:`onionsort.stages.label.LABEL_FORMATS` and
:data:`onionsort.stages.label_select.SELECT_FORMATS`.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

from onionsort.configs import option
from onionsort.configs.export import EXPORT_FORMATS as EXPORT_FORMATS
from onionsort.configs.export import ROS2_STORAGES as ROS2_STORAGES

#: Where torch runs: ``auto`` takes CUDA when a device is present, else the CPU.
DEVICES = ("auto", "cpu", "cuda")
BACKENDS = ("numpy", "numba")
METHODS = ("mmap-birl", "map-birl", "hidden-data-em", "maxent", "bc", "bc-em")
#: The four reward learners of the paper: what ``experiment`` runs by default
IRL_METHODS = METHODS[:4]
DIFFICULTY_LEVELS = ("clean", "realistic", "paper", "hard")
INSPECTION_VIEWS = 5
FUSION_RULES = ("noisy-or", "log-odds")
CALIBRATION_FORMS = ("log", "slopes", "powers")
INSPECTION_CAMERAS = ("both", "robot", "sorter")
LABEL_FORMATS = ("coco", "yolo")
#: What ``label import`` reads: the export's layouts and Label Studio's JSON export.
IMPORT_FORMATS = (*LABEL_FORMATS, "labelstudio")
SELECT_FORMATS = ("coco", "labelstudio")
#: How ``label select`` chooses steps: the least sure first, or uniformly at random.
SELECT_SAMPLES = ("uncertain", "random")
POSTERIOR_METHODS = ("mcmc", "laplace")


def seed(help: str = "root seed"):
    """``--seed``: the root seed, 0 by default."""
    return option(0, help=help)


def occlusion(default: float):
    """``--occlusion``: the chance that the passer-by occludes a step."""
    return option(default, help="probability that a step is occluded by the passer-by")


def steps_per_session():
    """``--steps-per-session``."""
    return option(20, help="abstract sorting steps per session")


def frames_per_step(help: str = "frames rendered per step"):
    """``--frames-per-step``."""
    return option(3, help=help)


def difficulty(help: str = "perception difficulty of the world"):
    """``--difficulty``: one of the world's levels."""
    return option("clean", choices=DIFFICULTY_LEVELS, help=help)


def models():
    """``--models``: the perception models folder."""
    return option(None, help="folder with detector.pt, state_classifier.pt and "
                             "inspection_classifier.pt, and optionally "
                             "robot_inspection_classifier.pt and robot_detector.pt for the "
                             "Sawyer's inspection "
                             "(default: the models shipped with onionsort)")


def device():
    """``--device {auto,cpu,cuda}``: where torch runs the perception models."""
    return option("auto", choices=DEVICES,
                  help="where torch runs: auto (CUDA when present, else the CPU), cpu or cuda")


def connect(what: str = "its Rerun recordings"):
    """``--connect URL``: also stream the command's Rerun recordings to a viewer over gRPC."""
    return option(None, metavar="URL",
                  help=f"also stream {what} to the Rerun viewer at URL, e.g. on another "
                       "machine (rerun+http://HOST:9876/proxy; start it there with `rerun`) "
                       "(default: none)")


def inspection_views():
    """``--inspection-views``: views the Sawyer takes of every onion."""
    return option(INSPECTION_VIEWS, help="views the Sawyer takes of every onion, turning and "
                                         "tilting it")


def miss_cost():
    """``--miss-cost``."""
    return option(None, help="cost of a blemished onion left on the line (default: from the "
                             "task's reward, 8)")


def waste_cost():
    """``--waste-cost``."""
    return option(None, help="cost of a good onion in the bin; the robot bins an onion when "
                             "P(blemished) >= waste / (waste + miss) (default: from the task's "
                             "reward, 8)")


def sorting_threshold(miss: float | None = None, waste: float | None = None) -> float:
    """The probability of a blemish from which the robot bins an onion: the cost threshold
    (:func:`perception.fusion.cost_threshold`) of ``miss`` (a blemished onion left on the line)
    and ``waste`` (a good onion in the bin), each by default the sorting task's own, from its
    true reward (:func:`irl.domains.onion_sorting.misplacement_costs`)."""
    from irl.domains.onion_sorting import misplacement_costs
    from perception.fusion import cost_threshold

    task_miss, task_waste = misplacement_costs()
    return cost_threshold(task_miss if miss is None else miss,
                          task_waste if waste is None else waste)


def fusion(help: str = "how the views are fused (default: the inspection classifier's own "
                       "rule)"):
    """``--fusion``: how the inspection's views are fused."""
    return option(None, choices=FUSION_RULES, help=help)


def backend():
    """``--backend {numpy,numba}``: the forward-backward kernels."""
    return option("numpy", choices=BACKENDS,
                  help="forward-backward kernels: numpy, or numba, compiled and equal to "
                       "rounding (pip install -e \".[fast]\"); used by mmap-birl and bc-em, "
                       "the other learners ignore it")


def posterior_method():
    """``--posterior-method {mcmc,laplace}``: how the posterior over rewards is sampled."""
    return option("mcmc", choices=POSTERIOR_METHODS,
                  help="how the posterior is drawn: mcmc, HMC chains on the exact gradient, "
                       "or laplace, a Gaussian at the MAP (fast)")


def session_swaps():
    """``--session-swaps``: MMAP-BIRL doubts how each whole session was read."""
    return option(False, help="mmap-birl: let a whole session's reads of the onion's class "
                              "have been backwards, at the rate the calibration measured on "
                              "its held-out sessions; its posterior weighs the reading of the "
                              "sessions the MAP implies, its complement, and every reading "
                              "one session from either")


def defer_below(needs: str):
    """``--defer-below P``: the robot defers where it is less sure than P of its action."""
    return option(None, metavar="P",
                  help="defer to a person where the robot is less sure than P that its next "
                       f"action is right: the learned policy's confidence in it ({needs}), "
                       "weighed over what an inspected onion may be by the inspection's "
                       "P(blemished); the onion goes to a check tray, counted apart (default: "
                       "never)")


def check_device(device: str) -> str:
    """``device`` if it is one of :data:`DEVICES`; a ``ValueError`` naming them otherwise."""
    if device not in DEVICES:
        raise ValueError(f"device must be one of {', '.join(DEVICES)}; got {device!r}")
    return device


def check_difficulty(level: str) -> str:
    """Refuse a name that is not a level of :data:`robot.difficulty.DIFFICULTY_LEVELS`."""
    from robot.difficulty import resolve_difficulty

    if not isinstance(level, str):
        raise TypeError(f"difficulty must be a level name; got {type(level).__name__}")
    resolve_difficulty(level)
    return level


def check_session_files(sessions) -> None:
    """Refuse an empty list of session files, or one that names a file that is not there."""
    if not sessions:
        raise ValueError("sessions must name at least one session file; got none")
    missing = [str(p) for p in sessions if not Path(p).is_file()]
    if missing:
        raise FileNotFoundError(f"no such session file(s): {', '.join(missing)}")


def methods_list(choices) -> Callable[[str], tuple[str, ...]]:
    """An option's type: one learner or several, comma-separated, each of ``choices``."""
    def parse(text: str) -> tuple[str, ...]:
        names = tuple(t.strip() for t in text.split(","))
        for name in names:
            if name not in choices:
                raise argparse.ArgumentTypeError(
                    f"invalid choice: {name!r} (choose from {', '.join(choices)})")
        return names
    return parse


def floats(text: str) -> tuple[float, ...]:
    """A comma-separated list of numbers, for argparse ``type=``."""
    try:
        return tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError:
        msg = f"expected comma-separated numbers; got {text!r}"
        raise argparse.ArgumentTypeError(msg) from None
