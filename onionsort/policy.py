"""The learned policy as a small runtime, for a robot's own process (a ROS 2 node, say).

A ``learn`` run folder holds the greedy policy (``model.json``) and, learned with
``--posterior``, how sure it is of each action in each state (``policy_confidence.json``).
:class:`SortingPolicy` loads them and answers, for a sorting state, the greedy action, its
confidence, and whether to defer the onion to a person at a threshold; its
:meth:`~SortingPolicy.inspection` is the robot's inspection as one call (an onion's views ->
P(blemished) -> a call), with the shipped perception models or a lab's fine-tuned ones::

    from onionsort.policy import SortingPolicy

    policy = SortingPolicy.load("runs/learn/mmap-birl")
    inspect = policy.inspection(models="runs/lab-models")   # or None: the shipped models
    verdict = inspect(views)              # views: the held onion's (h, w, 3) uint8 RGB images
    verdict.prediction, verdict.p_blemished
    action = policy.action(state)         # a SortAction, for a SortingState
    if policy.defers(state, 0.9, verdict.p_blemished):
        ...                               # hand the onion to a person

Importing it loads numpy, ``irl`` and the sorting loop's pure part (:mod:`robot.cell`); torch
and the models only when :meth:`~SortingPolicy.inspection` loads them; never the simulator
(pybullet), the writers (rerun, mcap) or Ray.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from irl.domains.onion_sorting import (
    SORTING_TASK,
    SortAction,
    SortingState,
    decode_state,
    encode_state,
    onion_sorting,
)
from irl.domains.task import TaskDescription
from robot.cell import check_confidence, confidence_in, greedy_actions

__all__ = ["CONFIDENCE_FILE", "CONFIDENCE_FORMAT", "MODEL_FILE", "MODEL_FORMAT",
           "SortingPolicy", "load_confidence", "load_policy"]

MODEL_FILE = "model.json"
MODEL_FORMAT = "onionsort.learned-model/1"
CONFIDENCE_FILE = "policy_confidence.json"
CONFIDENCE_FORMAT = "onionsort.policy-confidence/1"


def _read_run_json(run_dir: Path, name: str, missing: str, what: str, read):
    """``(path, read(document))`` of a run folder's JSON file ``name``, with one-line errors:
    ``missing`` says how to make it, ``what`` names it when it cannot be read."""
    path = Path(run_dir) / name
    if not path.is_file():
        raise FileNotFoundError(f"{run_dir} holds no {missing}")
    try:
        return path, read(json.loads(path.read_text()))
    except (json.JSONDecodeError, AttributeError, KeyError, TypeError, ValueError,
            UnicodeDecodeError) as exc:
        raise ValueError(f"{path} is not {what} ({exc})") from None


def load_policy(run_dir: Path, task: TaskDescription | None = None):
    """The greedy policy ``actions[s]`` (S,) of a learning run and its model.json, with clear
    errors; ``task`` (the onion-sorting task by default) gives the numbers of states and
    actions.

    Raises
    ------
    FileNotFoundError
        If the folder holds no model.json.
    ValueError
        If it is not a learned model with one action per state.
    """
    task = SORTING_TASK if task is None else task
    n_states, n_actions = task.n_states, task.n_actions
    path, (doc, actions) = _read_run_json(
        run_dir, MODEL_FILE,
        f"learned model (no {MODEL_FILE}); run `onionsort learn ... --out RUN_DIR` first",
        "a learned model",
        lambda doc: (doc, np.asarray(doc["policy_indices"], dtype=np.int64)))
    if actions.shape != (n_states,) or actions.min() < 0 or actions.max() >= n_actions:
        raise ValueError(f"{path}: the policy must give one action in [0, {n_actions}) for each "
                         f"of the {n_states} {task.name} states; got shape {actions.shape}")
    return actions, doc


def load_confidence(run_dir: Path, task: TaskDescription | None = None,
                    policy: np.ndarray | None = None, *, per_action: bool = False
                    ) -> np.ndarray:
    """``confidence[s]`` (S,): a learning run's confidence in its policy's action in each
    state, from ``policy_confidence.json`` (``onionsort learn --posterior``); with
    ``per_action``, ``confidence[s, a]`` (S, A), each action's. With ``policy`` (the run's
    actions per state), a file about another policy is refused.

    Raises
    ------
    FileNotFoundError
        If the folder holds no policy_confidence.json.
    ValueError
        If it cannot be read, is about another policy, or holds values outside [0, 1].
    """
    task = SORTING_TASK if task is None else task

    def read(doc: dict) -> tuple[np.ndarray, list[str]]:
        if doc.get("format") != CONFIDENCE_FORMAT:
            raise ValueError(f"format {doc.get('format')!r}")
        if per_action:
            conf = [[row["confidence"][a] for a in task.action_names] for row in doc["states"]]
        else:
            conf = [row["confidence"][row["map_action"]] for row in doc["states"]]
        return np.array(conf, float), [row["map_action"] for row in doc["states"]]

    path, (conf, named) = _read_run_json(
        run_dir, CONFIDENCE_FILE,
        f"posterior (no {CONFIDENCE_FILE}); learn with `onionsort learn ... --posterior` first",
        "a policy confidence file", read)
    if policy is not None and len(named) == len(policy) and \
            named != [task.action_names[int(a)] for a in policy]:
        raise ValueError(f"{path} is about another policy than {Path(run_dir) / MODEL_FILE}; "
                         "learn again with `onionsort learn ... --posterior`")
    if conf.shape[0] != task.n_states or np.any((conf < 0) | (conf > 1)):
        raise ValueError(f"{path}: one confidence in [0, 1] per {task.name} state is needed; "
                         f"got {conf.shape[0]}")
    return conf


def _state_index(state: SortingState | tuple[int, int, int] | int) -> SortingState:
    if isinstance(state, int | np.integer) and not isinstance(state, bool):
        return decode_state(int(state))
    try:
        return SortingState(*(int(x) for x in state))
    except (TypeError, ValueError):
        raise ValueError(f"state must be a SortingState (onion, end_effector, prediction) or a "
                         f"state index; got {state!r}") from None


@dataclass(frozen=True)
class SortingPolicy:
    """A greedy sorting policy, with how sure it is of each action where that is known.

    Attributes
    ----------
    actions : ndarray of shape (48,)
        The greedy action index in each state (``irl.domains.onion_sorting`` state indices).
    confidence_table : ndarray of shape (48, 5) or None
        The share of posterior reward samples whose greedy policy takes each action in each
        state (``policy_confidence.json``); None where the run has no posterior.
    method : str
        The learner (``"expert"`` for the task's own policy).
    run : Path or None
        The learn run folder it was loaded from.
    """

    actions: np.ndarray = field(repr=False)
    confidence_table: np.ndarray | None = field(default=None, repr=False)
    method: str = "expert"
    run: Path | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "actions", greedy_actions(self.actions))
        object.__setattr__(self, "confidence_table", check_confidence(self.confidence_table))
        if self.confidence_table is not None and self.confidence_table.ndim != 2:
            raise ValueError("confidence_table must hold each action's confidence, shape "
                             f"(48, 5); got shape {self.confidence_table.shape}")

    @classmethod
    def load(cls, run: Path | str) -> SortingPolicy:
        """The policy of the ``learn`` run folder ``run`` (its ``model.json``, and its
        ``policy_confidence.json`` where it has one).

        Raises
        ------
        FileNotFoundError
            If ``run`` holds no model.json.
        ValueError
            If a file is not what ``learn`` writes, or the confidence is about another policy.
        """
        run = Path(run)
        actions, doc = load_policy(run)
        confidence = None
        if (run / CONFIDENCE_FILE).is_file():
            confidence = load_confidence(run, policy=actions, per_action=True)
        return cls(actions, confidence, str(doc.get("method", "learned")), run)

    @classmethod
    def expert(cls) -> SortingPolicy:
        """The task's own policy (the expert's, from its true reward); no confidence."""
        return cls(onion_sorting().expert_policy().argmax(axis=1), None, "expert", None)

    def action(self, state: SortingState | tuple[int, int, int] | int) -> SortAction:
        """The greedy action in ``state`` (a :class:`SortingState`, its three factors, or
        its index)."""
        s = _state_index(state)
        return SortAction(int(self.actions[encode_state(s)]))

    def confidence(self, state: SortingState | tuple[int, int, int] | int,
                   action: SortAction | int | None = None,
                   p_blemished: float | None = None) -> float:
        """How sure the policy is that ``action`` (its own by default) is right in ``state``:
        the posterior share of reward samples whose greedy policy takes it; where the onion in
        focus was inspected and the inspection gave ``p_blemished``, weighed over what the
        onion may be (:func:`robot.cell.confidence_in`).

        Raises
        ------
        ValueError
            If the run has no posterior (learn it with ``--posterior``).
        """
        if self.confidence_table is None:
            where = "the task's own policy" if self.run is None else str(self.run)
            raise ValueError(f"{where} has no confidence; learn with `onionsort learn ... "
                             "--posterior`")
        s = _state_index(state)
        a = self.action(s) if action is None else SortAction(int(action))
        return confidence_in(self.confidence_table, s, int(a), p_blemished)

    def defers(self, state: SortingState | tuple[int, int, int] | int, threshold: float,
               p_blemished: float | None = None) -> bool:
        """Whether to hand the onion in focus to a person instead of acting: the confidence
        in the greedy action (:meth:`confidence`) is below ``threshold`` (in [0, 1])."""
        if isinstance(threshold, bool) or not isinstance(threshold, int | float) \
                or not 0.0 <= threshold <= 1.0:
            raise ValueError(f"threshold must be in [0, 1]; got {threshold!r}")
        return self.confidence(state, None, p_blemished) < threshold

    def inspection(self, models: Path | str | None = None, *, fusion: str | None = None,
                   miss_cost: float | None = None, waste_cost: float | None = None,
                   device: str = "auto"):
        """The robot's inspection as one call: ``inspect(views)`` on a held onion's views
        (each (h, w, 3) uint8 RGB) gives a verdict with its ``prediction`` (the task's
        ``good`` or ``bad``; ``unknown`` where no view shows an onion), the fused
        ``p_blemished`` and each view's (:class:`perception.inspection.Inspector`).

        Parameters
        ----------
        models : Path or str, optional
            A models folder (a lab's fine-tuned ones, ``--models``); the shipped ones by
            default. The Sawyer's own inspection classifier is read where the folder has one.
        fusion : {"noisy-or", "log-odds"}, optional
            How the views are fused (the classifier's own rule by default).
        miss_cost, waste_cost : float, optional
            The costs of a blemished onion left on the line and of a good one binned, whose
            threshold calls an onion blemished (the task's own by default).
        device : {"auto", "cpu", "cuda"}

        Raises
        ------
        FileNotFoundError
            Naming a model file the folder lacks.
        """
        from onionsort.configs.common import sorting_threshold
        from onionsort.perception_models import PerceptionModels

        loaded = PerceptionModels.load(models, device)
        return loaded.inspector(rule=fusion, threshold=sorting_threshold(miss_cost, waste_cost),
                                camera="robot")
