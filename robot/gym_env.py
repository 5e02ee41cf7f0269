"""The Sawyer sorting station as a Gymnasium environment, ``onionsort/Sorting-v0``.

Importing :mod:`robot` registers it, so ``gymnasium.make("onionsort/Sorting-v0", ...)`` builds a
:class:`SortingEnv` with the keyword arguments given. One episode is one run of the sorting loop
(:class:`robot.cell.SortingRun`), one action a step, as :func:`robot.evaluation.evaluate_policy`
runs it: the same station (:class:`robot.station.SawyerStation`), line-up, seed, step budget
and counting (:class:`robot.tally.SortingTally`), so a fixed policy rolled out here from
``reset(seed=k)`` gives the TP/FP/TN/FN of ``onionsort evaluate`` with ``--seed k`` (and the
same onions, inspection and difficulty).

Spaces
------
action : ``Discrete(5)``
    A :class:`~irl.domains.onion_sorting.SortAction`: 0 CLAIM, 1 PICK, 2 INSPECT,
    3 PLACE_ON_CONVEYOR, 4 PLACE_IN_BIN. An action that does nothing in the current state does
    nothing physically (and still spends a step).
observation : ``Dict``
    - ``"image"``: ``Box(0, 255, (H, W, 3), uint8)``, the main camera's RGB ``rgb[v, u, c]``
      after the action (H, W of ``camera``, 240 x 320 by default; with the difficulty's image
      effects);
    - ``"state"``: ``MultiDiscrete([4, 4, 3])``, the abstract state read off the world as its
      factors ``(onion, end_effector, prediction)`` (:class:`~irl.domains.onion_sorting.
      SortingState`; ``encode_state(obs["state"])`` is the flat index the policies use, also in
      ``info["state_index"]``). The prediction factor is what the robot *perceived*.

Reward ``R[s, a] = phi[s, a] . theta`` of the state before the action and the action: the
domain's true weights by default, or the learned weights of a ``model.json`` written by
``onionsort learn`` (``reward_model``).

An episode *terminates* when every onion has a fate (binned, or set back on the belt after
inspection) and is *truncated* when the step budget ``n_onions * max_steps_per_onion`` is spent.
``info`` carries the running ``tp``, ``fp``, ``tn``, ``fn`` over the onions decided so far,
``state_index``, ``onion`` (in focus), ``perceived`` (the classifier's answer if the action
inspected) and ``fate`` (if the action decided the onion); the last step's ``info["result"]``
is the episode's :class:`~robot.evaluation.SortingResult`, where undecided onions count as left
on the line.

The first observation's image is rendered before any action; under a difficulty with image
noise its noise comes from a stream of its own, so that the main camera's images are those of
``evaluate_policy(..., render=True)``, the way ``onionsort evaluate`` runs when it records to
Rerun (its default). The inspection views never depend on what the main camera rendered.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, ClassVar, Literal

import gymnasium
import numpy as np
from gymnasium import spaces

from irl.domains.onion_sorting import (
    FACTOR_SIZES,
    N_ACTIONS,
    SORTING_TASK,
    SortAction,
    SortingState,
    encode_state,
    onion_sorting,
)
from robot.camera import CameraSpec
from robot.cell import SortingRun
from robot.classifier import GROUND_TRUTH, Classifier, check_classifier
from robot.difficulty import Difficulty, resolve_difficulty
from robot.station import INSPECTION_VIEWS, SawyerStation

__all__ = ["SortingEnv", "sorting_reward"]

_PREVIEW_TAG = 0x6E76  # spawn key of the first image's noise stream


def sorting_reward(reward_model: str | Path | None = None) -> np.ndarray:
    """The reward table ``R[s, a]`` (48, 5) of the sorting domain.

    Parameters
    ----------
    reward_model : str or Path, optional
        A ``model.json`` written by ``onionsort learn`` (or the run folder holding it): its
        learned weights ``theta``, one per feature name of the task. None: the domain's true
        weights.

    Raises
    ------
    FileNotFoundError
        If ``reward_model`` names no file (or a folder without ``model.json``).
    ValueError
        If the file is not a learned model with finite weights for exactly the task's features.
    """
    domain = onion_sorting()
    if reward_model is None:
        return domain.mdp.reward(domain.true_theta)
    if not isinstance(reward_model, str | Path):
        raise TypeError(f"reward_model must be a path to a model.json or None; got "
                        f"{type(reward_model).__name__}")
    path = Path(reward_model)
    if path.is_dir():
        path = path / "model.json"
    if not path.is_file():
        raise FileNotFoundError(f"reward_model {path} is not a file; pass a model.json written "
                                "by `onionsort learn` (or its run folder)")
    try:
        theta_by_name = json.loads(path.read_text())["theta"]
    except (json.JSONDecodeError, KeyError, TypeError, UnicodeDecodeError) as exc:
        raise ValueError(f"reward_model {path} is not a learned model with reward weights "
                         f"'theta' ({exc!r})") from None
    if not isinstance(theta_by_name, dict):
        raise ValueError(f"reward_model {path} is not a learned model: its 'theta' must map "
                         f"feature names to weights; got {type(theta_by_name).__name__}")
    names = set(theta_by_name)
    expected = SORTING_TASK.feature_names
    if names != set(expected):
        raise ValueError(f"reward_model {path} must give theta for exactly the features "
                         f"{list(expected)}; got {sorted(names)}")
    try:
        theta = np.array([float(theta_by_name[k]) for k in expected])
    except (TypeError, ValueError):
        raise ValueError(f"reward_model {path} must give numeric theta; got "
                         f"{theta_by_name}") from None
    if not np.all(np.isfinite(theta)):
        raise ValueError(f"reward_model {path} must give finite theta; got {theta.tolist()}")
    return domain.mdp.reward(theta)


def _check_int(name: str, value: Any, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
        raise ValueError(f"{name} must be an int >= {low}; got {value!r}")
    return int(value)


class SortingEnv(gymnasium.Env):
    """The Sawyer sorting a line-up of onions, one abstract action per step (see the module
    docstring for the spaces, reward and episode).

    Parameters
    ----------
    n_onions, n_blemished : int
        Line-up size and how many of its onions are blemished (as ``onionsort evaluate``:
        50 and 30).
    classify : callable or "ground-truth"
        ``classify(views) -> Prediction or Verdict`` on the onion's inspection views
        (:data:`robot.classifier.Classifier`), or perfect perception.
    difficulty : Difficulty or str
        Perception difficulty of the station (:mod:`robot.difficulty`).
    max_steps_per_onion : int
        The step budget is ``n_onions * max_steps_per_onion`` actions.
    move_steps : int
        Physics steps per arm motion.
    reward_model : str or Path, optional
        A learned ``model.json`` whose reward replaces the true one (:func:`sorting_reward`).
    camera : CameraSpec, optional
        The main camera, whose images are observed (the station's default if None).
    render_mode : {"rgb_array"} or None
        ``render()`` returns the last observed image.
    inspection_views : int
        Views the robot takes of every onion it inspects.
    """

    metadata: ClassVar[dict[str, Any]] = {
        "render_modes": ["rgb_array"], "render_fps": 0.5}  # the station: 2 s an action

    def __init__(
        self,
        *,
        n_onions: int = 50,
        n_blemished: int = 30,
        classify: Classifier | Literal["ground-truth"] = GROUND_TRUTH,
        difficulty: Difficulty | str = "clean",
        max_steps_per_onion: int = 12,
        move_steps: int = 120,
        reward_model: str | Path | None = None,
        camera: CameraSpec | None = None,
        render_mode: str | None = None,
        inspection_views: int = INSPECTION_VIEWS,
    ) -> None:
        self.n_onions = _check_int("n_onions", n_onions, 1)
        self.n_blemished = _check_int("n_blemished", n_blemished, 0)
        if self.n_blemished > self.n_onions:
            raise ValueError(f"n_blemished must be <= n_onions={self.n_onions}; got "
                             f"{n_blemished}")
        self.max_steps_per_onion = _check_int("max_steps_per_onion", max_steps_per_onion, 1)
        self.move_steps = _check_int("move_steps", move_steps, 2)
        check_classifier(classify)
        if camera is not None and not isinstance(camera, CameraSpec):
            raise TypeError(f"camera must be a CameraSpec or None; got {type(camera).__name__}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or "
                             f"None; got {render_mode!r}")
        self.classify = classify
        self.inspection_views = _check_int("inspection_views", inspection_views, 1)
        self.difficulty = resolve_difficulty(difficulty)
        self.camera = CameraSpec() if camera is None else camera
        self.render_mode = render_mode
        self.reward_model = None if reward_model is None else Path(reward_model)
        self.reward_table = sorting_reward(reward_model)  # R[s, a]
        self.budget = self.n_onions * self.max_steps_per_onion
        self.action_space = spaces.Discrete(N_ACTIONS)
        self.observation_space = spaces.Dict({
            "image": spaces.Box(0, 255, (self.camera.height, self.camera.width, 3), np.uint8),
            "state": spaces.MultiDiscrete(np.array(FACTOR_SIZES, dtype=np.int64)),
        })
        self._station: SawyerStation | None = None
        self._run: SortingRun | None = None
        self._image: np.ndarray | None = None
        self._over = True

    # -- Gymnasium API -----------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None
              ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Build the station for a new line-up; ``seed`` seeds it as ``evaluate``'s seed does
        (without one, the line-up's seed is drawn from the environment's generator).
        ``options`` is accepted and unused."""
        super().reset(seed=seed)
        if options is not None and not isinstance(options, dict):
            raise ValueError(f"options must be a dict or None; got {type(options).__name__}")
        station_seed = int(self.np_random.integers(2**63)) if seed is None else int(seed)
        self._close_station()
        station = SawyerStation(self.classify, n_onions=self.n_onions,
                                n_blemished=self.n_blemished, seed=station_seed,
                                move_steps=self.move_steps,
                                camera=self.camera, difficulty=self.difficulty,
                                inspection_views=self.inspection_views)
        self._station = station.__enter__()
        self._run = SortingRun(station, self.n_onions, station.reader, truth=station.blemished,
                               max_steps_per_onion=self.max_steps_per_onion)
        self._over = False
        self._image = self._first_image(station_seed)
        state = station.state
        info = {**self._run.tally.counts, "state_index": encode_state(state), "onion": None,
                "perceived": None, "fate": None}
        return self._observation(state, self._image), info

    def step(self, action) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """Execute one abstract action on the station."""
        if self._station is None or self._run is None:
            raise RuntimeError("call reset() before step()")
        if self._over:
            raise RuntimeError("the episode is over; call reset() to start another")
        if isinstance(action, bool) or not self.action_space.contains(action):
            raise ValueError(f"action must be an int in [0, {N_ACTIONS}) (a SortAction); got "
                             f"{action!r}")
        a = SortAction(int(action))
        done, fate = self._run.act(a)
        reward = float(self.reward_table[encode_state(done.state), int(a)])
        terminated = self._run.tally.complete
        truncated = not terminated and self._run.n_steps >= self.budget
        self._image = self._station.render().rgb
        info: dict[str, Any] = {**self._run.tally.counts,
                                "state_index": encode_state(done.next_state),
                                "onion": done.onion, "perceived": done.perceived, "fate": fate}
        if terminated or truncated:
            self._over = True
            info["result"] = self._run.result()
        return (self._observation(done.next_state, self._image), reward, terminated, truncated,
                info)

    def render(self) -> np.ndarray | None:
        """The last observed image (H, W, 3) uint8 in ``"rgb_array"`` mode; None otherwise."""
        if self.render_mode is None or self._image is None:
            return None
        return self._image.copy()

    def close(self) -> None:
        """Disconnect the station's physics client (safe to call more than once)."""
        self._close_station()
        super().close()

    # -- helpers -----------------------------------------------------------------------------
    def _close_station(self) -> None:
        if self._station is not None:
            self._station.__exit__(None, None, None)
            self._station = None

    def _first_image(self, station_seed: int) -> np.ndarray:
        """The main camera before the first action, its image noise drawn from a stream of its
        own so that the station's own draws (and so its inspections) are left as they are."""
        effects = self._station.cameras.effects
        own = effects.rng
        seq = np.random.SeedSequence(station_seed, spawn_key=(_PREVIEW_TAG,))
        effects.rng = np.random.default_rng(seq)
        try:
            return self._station.render().rgb
        finally:
            effects.rng = own

    @staticmethod
    def _observation(state: SortingState, image: np.ndarray) -> dict[str, np.ndarray]:
        return {"image": np.array(image, dtype=np.uint8, copy=True),
                "state": np.array([int(x) for x in state], dtype=np.int64)}
