"""The Sawyer sorting station: the robot executes sorting actions on a line-up of onions.

The workcell is the human sessions' (:func:`robot.scene.build_workcell`, the :class:`StopGate`,
the main :class:`~robot.camera.CameraSpec`), with the Sawyer standing where the sorter stood,
facing the belt. It inspects at the sorter's inspection spot, through a camera of its own
(:data:`ROBOT_INSPECTION_CAMERA`: the spot as the sorter's camera sees it, at twice the
resolution, as a real cell would fit its inspection station with a sharper camera than the one
that watches the person; the difficulty's image effects apply to it as to every camera).
Each :class:`~irl.domains.onion_sorting.SortAction` is a motion primitive:

- CLAIM raises the gate and runs the belt until the next onion of the line-up waits at the
  pick spot (an indexing belt: it runs only while the station claims; onions placed back
  downstream ride away with it and leave the belt at its end);
- PICK moves above the waiting onion, descends, switches the suction on, lowers the gate and
  lifts the onion to the hover pose;
- INSPECT holds the onion up in front of the inspection camera and shows it from every side:
  the wrist turns it through ``inspection_views`` evenly spaced angles, every other view tilted
  so that its underside faces the camera (:func:`inspection_poses`); the classifier reads the
  views together and answers the onion's class (it may abstain only if no view shows the onion);
- PLACE_ON_CONVEYOR sets the onion on the belt downstream of the gate, where it rides away (or,
  if it was never inspected, back at the gate, where it waits to be picked again), and returns
  above the pick spot;
- PLACE_IN_BIN moves over the bin and releases the onion, which drops into it.

For 3D logging, :meth:`SawyerStation.world_state` snapshots the work cell, the gate, the onions
on the belt, held or in the bin (with their classes), both cameras and the Sawyer's joints
(:mod:`robot.world`); :func:`station_robot` describes the Sawyer as it stands here before a
station exists (a logger draws it from its URDF).

An action that the MDP says does nothing in the current state (``next_state(s, a) == s``) does
nothing physically. After every action the state read off the world (:meth:`SawyerStation.state`)
must equal ``next_state(s, a, blemished=<the class the classifier perceived>)``: the prediction
factor is what the robot *perceived*, so perception errors propagate exactly as in the MDP.

Onions are static, mass-0 bodies that the belt carries kinematically (as in the human
sessions), so the suction grasp is kinematic too (``Sawyer.grasp(body, kinematic=True)``): the
held onion's pose is reset to the flange's after every physics step, and on release it is set
down on the belt or dropped to its place in the bin. Positions are world metres, shape (3,);
joint vectors have shape (7,).
"""

from __future__ import annotations

import logging
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Literal, NamedTuple, Protocol, runtime_checkable

import numpy as np
import pybullet as p

from irl.domains.onion_sorting import (
    Location,
    Prediction,
    SortAction,
    SortingState,
    next_state,
)
from robot.assets import sawyer_urdf
from robot.camera import (
    CameraImage,
    CameraSpec,
    Lighting,
    boxes_from_segmentation,
    render,
    sample_lighting,
)
from robot.difficulty import (
    DIFFICULTY_LEVELS,
    Difficulty,
    ImageEffects,
    difficulty_rng,
    resolve_difficulty,
)
from robot.inspection_poses import INSPECTION_TILT, INSPECTION_VIEWS, inspection_poses
from robot.labels import OnionLabel
from robot.look import Look, draw_look, look_rng
from robot.onions import OnionAppearance, onion_texture, sample_appearance, save_texture
from robot.scene import GATE_X, StopGate, build_workcell, connect
from robot.state_map import (
    BELT_HALF_LENGTH,
    BELT_TOP,
    BIN_CENTER,
    BIN_TOP,
    PICK_SPOT,
    WorldSnapshot,
    state_of_world,
)
from robot.world import Pose, RobotState, WorldProbe, WorldState, camera_pose, robot_state

__all__ = [
    "GROUND_TRUTH",
    "INSPECTION_TILT",
    "INSPECTION_VIEWS",
    "ROBOT_BASE",
    "ROBOT_BASE_YAW",
    "ROBOT_INSPECTION_CAMERA",
    "ROBOT_TARGETS",
    "SAWYER_JOINTS",
    "START_STATE",
    "STEP_DURATION_S",
    "Classifier",
    "InspectionLabel",
    "SawyerStation",
    "SequentialClassifier",
    "StationStep",
    "Verdict",
    "inspection_poses",
    "make_lineup",
    "station_robot",
]

logger = logging.getLogger(__name__)

class InspectionLabel(NamedTuple):
    """The ground truth of one onion in an inspection view: its box ``(x_min, y_min, x_max,
    y_max)`` (exclusive max), its class, its visible pixels, and how many of them show rot
    (None where not measured)."""

    box: tuple[int, int, int, int]
    blemished: bool
    visible_pixels: int
    rot_pixels: int | None = None


class Verdict(Protocol):
    """What a classifier may answer instead of a bare :class:`Prediction`: the class, with the
    probability behind it (``perception.InspectionVerdict`` is one)."""

    @property
    def prediction(self) -> int: ...

    @property
    def p_blemished(self) -> float | None: ...

    @property
    def view_p_blemished(self) -> tuple[float | None, ...]: ...


Classifier = Callable[[list[np.ndarray]], "Prediction | Verdict"]
"""``classify(views) -> Prediction or Verdict``: the held onion's class from all its inspection
views (each (h, w, 3) uint8 RGB, in the order of :func:`inspection_poses`): GOOD or BAD, or
UNKNOWN to abstain (no view shows an onion)."""


@runtime_checkable
class SequentialClassifier(Protocol):
    """A :data:`Classifier` that reads the views one at a time, so that the robot can stop
    showing an onion once its call is settled (``perception.Inspector`` is one).

    ``view_probabilities(views)`` gives each view's probability (None where it shows no
    onion); ``settled(view_p, remaining)`` whether ``remaining`` more views could still change
    the call on those; ``verdict(view_p)`` the call.
    """

    def __call__(self, views: list[np.ndarray]) -> Verdict: ...

    def view_probabilities(self, views: list[np.ndarray]) -> list[float | None]: ...

    def settled(self, view_p: list[float | None], remaining: int) -> bool: ...

    def verdict(self, view_p: list[float | None]) -> Verdict: ...


GROUND_TRUTH: Literal["ground-truth"] = "ground-truth"
"""Pass as ``classify`` to perceive every inspected onion's true class (perfect perception)."""

ROBOT_BASE = np.array([0.30, 0.70, 0.90])
"""Where the Sawyer's base stands: behind the sorter's stance, on a pedestal."""
ROBOT_BASE_YAW = -np.pi / 2
"""The base faces -y, across the belt (as the sorter did)."""
SAWYER_JOINTS = tuple(f"right_j{k}" for k in range(7))
"""The Sawyer's joints in the order of a joint vector ``q`` (7,) (its URDF's names)."""
STEP_DURATION_S = 2.0
"""The station's clock per action (s): action ``t`` runs from ``t * STEP_DURATION_S`` to
``(t + 1) * STEP_DURATION_S`` (the difficulty's lighting drift follows it)."""

#: Flange (``right_l6``'s frame, :meth:`Sawyer.end_effector`) to the held onion's surface: the
#: link's tool face is 2.45 cm out along the flange's axis, the suction cup 1 cm more.
_GAP = 0.035
_INSPECT_CENTER = np.array([0.02, 0.26, 1.465])  # on the inspection camera's optical axis

#: Where the Sawyer's flange goes for each location, shape (3,) each; the flange points down.
#: CONVEYOR is above the pick spot; FACE holds the onion on the inspection camera's axis, about
#: 18 cm in front of it; BIN is over the bin's centre, the onion clear of the rim.
ROBOT_TARGETS: dict[Location, np.ndarray] = {
    Location.CONVEYOR: np.array([PICK_SPOT[0], PICK_SPOT[1], BELT_TOP + 0.17]),
    Location.HOVER: np.array([0.14, 0.22, 1.12]),
    Location.FACE: _INSPECT_CENTER + np.array([0.0, 0.0, 0.04 + _GAP]),
    Location.BIN: np.array([BIN_CENTER[0], BIN_CENTER[1], BIN_TOP + 0.16]),
}

START_STATE = SortingState(Location.CONVEYOR, Location.CONVEYOR, Prediction.GOOD)
"""The station's first state: the MDP's initial state with nothing in focus (as if an onion
had just been left on the line), the flange above the pick spot. The policy must CLAIM."""

_LANES = (-0.04, 0.08)  # y range the onions ride in (as in robot.scene)
_SPACING = 0.25  # belt travel between consecutive onions of the line-up
_GATE_FACE = GATE_X - 0.02  # upstream face of the raised stop gate
_PLACE_X = GATE_X + 0.12  # where the robot sets inspected onions back on the belt
_PARKED = (0.0, 0.0, -10.0)  # bodies off the belt (not yet arrived, or ridden away)
_SETTLE_TOL, _SETTLE_STEPS, _MAX_SETTLE = 0.005, 20, 8  # corrective motions after a move
#: The check tray on the floor beside the bin, where deferred onions wait for a person: its
#: first slot; the others follow along x.
_TRAY = np.array([BIN_CENTER[0] + 0.42, BIN_CENTER[1], 0.0])
_BIN_SLOTS = 9  # onions per layer in the bin (3 x 3)
_BIN_LAYERS = 4
_GRIPPER_RGB = (72.0, 72.0, 78.0)  # the suction gripper's grey, drawn over a held onion


ROBOT_INSPECTION_CAMERA = CameraSpec(
    width=320, height=240, fov_deg=38.0, eye=(0.02, 0.08, 1.50), target=(0.02, 0.32, 1.45),
    frame_id="inspection",
)
"""The Sawyer's inspection camera: the sorter's inspection spot (:data:`INSPECTION_CAMERA`'s
pose) at twice its resolution, 320x240 over a 38-degree field of view, so that a held onion
(6.4-9 cm across, 18 cm away) fills about 200 pixels of it instead of 50."""

def _down(yaw: float, tilt: float = 0.0) -> tuple[float, ...]:
    """Quaternion (x, y, z, w) of the flange pointing down, turned by ``yaw`` about z, then
    tilted by ``tilt`` about x so that what hangs from it swings towards -y (the inspection
    camera)."""
    down = p.getQuaternionFromEuler([np.pi, 0.0, -yaw])
    if not tilt:
        return tuple(down)
    turn = p.getQuaternionFromEuler([-tilt, 0.0, 0.0])
    return tuple(p.multiplyTransforms([0, 0, 0], turn, [0, 0, 0], down)[1])


def station_robot(positions: np.ndarray | None = None) -> RobotState:
    """The Sawyer as it stands in the station: its URDF, its base on the pedestal
    (:data:`ROBOT_BASE`, turned by :data:`ROBOT_BASE_YAW`), its joints :data:`SAWYER_JOINTS` at
    ``positions`` (7,) (zeros by default). What a logger needs to draw the robot before a
    station runs; :meth:`SawyerStation.world_state` reads the same from the simulator."""
    q = np.zeros(len(SAWYER_JOINTS)) if positions is None else positions
    half = ROBOT_BASE_YAW / 2
    return RobotState(name="sawyer", urdf=sawyer_urdf(),
                      base=Pose(ROBOT_BASE, [0.0, 0.0, np.sin(half), np.cos(half)]),
                      joint_names=SAWYER_JOINTS, positions=q)


def make_lineup(
    n_onions: int, n_blemished: int, rng: np.random.Generator
) -> tuple[OnionAppearance, ...]:
    """``n_onions`` appearances, exactly ``n_blemished`` of them blemished, in random order."""
    if isinstance(n_onions, bool) or not isinstance(n_onions, int | np.integer) or n_onions < 1:
        raise ValueError(f"n_onions must be an int >= 1; got {n_onions!r}")
    if (isinstance(n_blemished, bool) or not isinstance(n_blemished, int | np.integer)
            or not 0 <= n_blemished <= n_onions):
        raise ValueError(
            f"n_blemished must be an int in [0, n_onions={n_onions}]; got {n_blemished!r}"
        )
    blemished = np.zeros(n_onions, bool)
    blemished[:n_blemished] = True
    return tuple(sample_appearance(rng, bool(b)) for b in rng.permutation(blemished))


@dataclass
class _LineUpOnion:
    """One onion of the line-up: its body and where it is.

    ``place`` is ``"queued"`` (upstream, not yet claimed), ``"waiting"`` (claimed, at the gate),
    ``"held"``, ``"belt"`` (set back on the belt), ``"bin"`` or ``"gone"`` (rode off the belt).
    """

    index: int
    body: int
    appearance: OnionAppearance
    position: np.ndarray
    place: str = "queued"
    perceived: Prediction | None = None


@dataclass(frozen=True)
class StationStep:
    """What one action did.

    Attributes
    ----------
    state, next_state : SortingState
        The state before and after, both read off the world.
    action : SortAction
    onion : int or None
        Line-up index of the onion in focus after the action (None before the first claim).
    perceived : Prediction or None
        The classifier's answer, if this action inspected an onion.
    inspection : ndarray of shape (h, w, 3) or None
        uint8 RGB of the first inspection view, if this action inspected an onion.
    views : tuple of ndarray of shape (h, w, 3)
        Every inspection view of the onion (empty if this action inspected none).
    p_blemished : float or None
        The classifier's probability that the onion is blemished, where it gave one.
    view_p_blemished : tuple of (float or None)
        Its probability from each view alone, where it gave them (None: no onion found).
    image : CameraImage or None
        The main camera after the action, if the station renders every step.
    q : ndarray of shape (7,)
        The Sawyer's joint positions after the action.
    reach_error : float
        Largest final flange position error (m) of the action's arm motions; 0 if none.
    """

    state: SortingState
    action: SortAction
    next_state: SortingState
    onion: int | None
    perceived: Prediction | None = None
    inspection: np.ndarray | None = field(default=None, repr=False)
    image: CameraImage | None = field(default=None, repr=False)
    q: np.ndarray = field(default_factory=lambda: np.zeros(7), repr=False)
    reach_error: float = 0.0
    views: tuple[np.ndarray, ...] = field(default=(), repr=False)
    p_blemished: float | None = None
    view_p_blemished: tuple[float | None, ...] = field(default=(), repr=False)

    @property
    def changed(self) -> bool:
        """Whether the action did anything (``next_state != state``)."""
        return self.next_state != self.state


class SawyerStation:
    """The Sawyer sorting a line-up of onions, in its own headless PyBullet client.

    Use as a context manager; :meth:`step` executes one action.

    Parameters
    ----------
    classify : callable or "ground-truth"
        ``classify(views) -> Prediction or Verdict`` from the onion's inspection views (each
        (h, w, 3) uint8): GOOD, BAD, or UNKNOWN to abstain (an onion it never classifies counts
        as GOOD); :data:`GROUND_TRUTH` perceives each onion's true class (the views are still
        taken).
    n_onions : int
        Onions in the line-up.
    n_blemished : int
        How many of them are blemished (exactly).
    seed : int or numpy.random.SeedSequence
        Seeds the line-up (order, appearances, lanes) and the scene (tints, lighting).
    move_steps : int
        Physics steps of each arm motion between poses (short vertical motions take half).
    render_every_step : bool
        Render the main camera after every action (:attr:`StationStep.image`).
    camera, inspection : CameraSpec
        The main camera and the inspection camera (:data:`ROBOT_INSPECTION_CAMERA`).
    inspection_views : int
        Views of every inspected onion (:func:`inspection_poses`): the most it takes.
    stop_when_settled : bool
        With a :class:`SequentialClassifier`, stop showing an onion as soon as its call can no
        longer change (under ``noisy-or``, a view that shows rot settles a blemish at once):
        the call all its views would give, from fewer. The image noise is one stream per run,
        so later onions' views draw it otherwise than with every view taken. False: always
        take every view.
    label_blemishes : bool
        Measure the rot each inspection view shows, for :meth:`inspection_labels` (one more
        render per view; for datasets).
    difficulty : Difficulty or str
        Perception difficulty (:mod:`robot.difficulty`), or a level's name: the onions'
        blemishes, and the image effects and the gripper covering part of the onion on the
        inspection view (and the main camera's renders); ``"clean"`` is today's station.
    randomize_look : bool
        Draw the station's look from ``seed`` (:mod:`robot.look`: light, surface colours, the
        cameras' exposure and white balance), for training data; off, it renders exactly as
        without it.

    Attributes
    ----------
    lineup : tuple of OnionAppearance
        The onions in the order they arrive.
    blemished : ndarray of shape (n_onions,)
        Their true classes.
    focus : int or None
        Line-up index of the onion in focus (the last one claimed).
    n_claimed : int
        Onions claimed so far.
    lighting : Lighting
    """

    def __init__(
        self,
        classify: Classifier | Literal["ground-truth"],
        *,
        n_onions: int = 50,
        n_blemished: int = 30,
        seed: int | np.random.SeedSequence = 0,
        move_steps: int = 120,
        render_every_step: bool = False,
        camera: CameraSpec | None = None,
        inspection: CameraSpec = ROBOT_INSPECTION_CAMERA,
        difficulty: Difficulty | str = DIFFICULTY_LEVELS["clean"],
        inspection_views: int = INSPECTION_VIEWS,
        stop_when_settled: bool = True,
        label_blemishes: bool = False,
        randomize_look: bool = False,
    ) -> None:
        if isinstance(classify, str):
            if classify != GROUND_TRUTH:
                raise ValueError(
                    f"classify must be a callable rgb -> Prediction or {GROUND_TRUTH!r}; "
                    f"got {classify!r}"
                )
        elif not callable(classify):
            raise TypeError(
                f"classify must be a callable rgb -> Prediction or {GROUND_TRUTH!r}; got "
                f"{type(classify).__name__}"
            )
        if isinstance(move_steps, bool) or not isinstance(move_steps, int | np.integer) \
                or move_steps < 2:
            raise ValueError(f"move_steps must be an int >= 2; got {move_steps!r}")
        self.poses = inspection_poses(inspection_views)
        self.stop_when_settled = bool(stop_when_settled)
        self.label_blemishes = bool(label_blemishes)
        self.randomize_look = bool(randomize_look)
        self.look: Look | None = None
        self._blemish_probe = None
        seq = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
        self.difficulty = resolve_difficulty(difficulty)
        self._difficulty_seq = seq
        lineup_seq, self._lanes_seq, self._scene_seq = seq.spawn(3)
        self.lineup = make_lineup(n_onions, n_blemished, np.random.default_rng(lineup_seq))
        self.blemished = np.array([look.blemished for look in self.lineup])
        self.classify = classify
        self.move_steps = int(move_steps)
        self.render_every_step = bool(render_every_step)
        self.camera = CameraSpec() if camera is None else camera
        self.inspection = inspection
        self.client: int | None = None
        self.focus: int | None = None
        self.n_claimed = 0

    # -- lifecycle ---------------------------------------------------------------------------
    def __enter__(self) -> SawyerStation:
        from robot.sawyer import Sawyer

        self.client = connect()
        self._scene_rng = np.random.default_rng(self._scene_seq)  # the same world on every entry
        self.effects = ImageEffects(self.difficulty, difficulty_rng(self._difficulty_seq))
        # the inspection camera's noise is a stream of its own: whether the main camera renders
        # (a Rerun log, a Gymnasium observation) never changes what the detector sees
        self.inspection_effects = self.effects.with_rng(difficulty_rng(self._difficulty_seq, 1))
        # and so has the view before the first action, rendered only for a recording of it
        self._initial_effects = self.effects.with_rng(difficulty_rng(self._difficulty_seq, 2))
        self._clock = 0.0
        try:
            self.lighting: Lighting = sample_lighting(self._scene_rng)
            self.workcell = build_workcell(self.client, self._scene_rng)
            self.gate = StopGate(self.client)
            self.workcell["pedestal"] = self._pedestal()
            if self.randomize_look:  # from a stream of its own: the line-up is unchanged
                self.look = draw_look(look_rng(self._difficulty_seq))
                self.lighting = self.look.lighting
                self.look.paint(self.client, self.workcell)
            self.arm = Sawyer(self.client, base_position=ROBOT_BASE, base_yaw=ROBOT_BASE_YAW)
            self._q_rest = self.arm.inverse_kinematics(ROBOT_TARGETS[Location.CONVEYOR])
            self.arm.reset(self._q_rest)
            if self.label_blemishes:
                from robot.blemishes import BlemishProbe

                self._blemish_probe = BlemishProbe(self.client)
            self._onions = self._make_onions()
            bodies = {f"workcell/{name}": body for name, body in self.workcell.items()}
            bodies["gate"] = self.gate.body
            bodies.update({f"onions/{o.index}": o.body for o in self._onions})
            self._probe = WorldProbe(self.client, bodies, classes={
                f"onions/{o.index}": int(o.appearance.blemished) for o in self._onions})
            self._urdf = sawyer_urdf()
        except BaseException:
            self.__exit__(None, None, None)
            raise
        self.focus, self.n_claimed = None, 0
        # the last inspection's views as rendered and, with label_blemishes, their labels
        self.last_views: list[CameraImage] = []
        self.last_labels: list[list[InspectionLabel]] = []
        self._travel = -_SPACING  # belt travel; onion k waits at the gate at travel k*_SPACING
        self._in_bin = 0
        self._on_tray = 0
        self._arrange_belt()
        return self

    def __exit__(self, *exc) -> None:
        if self.client is not None:
            p.disconnect(physicsClientId=self.client)
            self.client = None

    def _require_client(self) -> int:
        if self.client is None:
            raise RuntimeError("SawyerStation must be entered (`with SawyerStation(...)`)")
        return self.client

    def world_state(self) -> WorldState:
        """The world now, for 3D logging (:class:`robot.world.WorldState`): the work cell (its
        pedestal too), the gate and the onions that are in the world (on the belt, held, in the
        bin; not those parked out of it), each onion with its true class; the optical frames of
        the main camera and the inspection view; the Sawyer's base and joint positions."""
        client = self._require_client()
        shapes = tuple(s for s in self._probe.shapes() if s.pose.position[2] > _PARKED[2] / 2)
        cameras = {spec.frame_id: camera_pose(spec) for spec in (self.camera, self.inspection)}
        return WorldState(shapes=shapes, cameras=cameras,
                          robot=robot_state(client, self.arm.body, self.arm.joints,
                                            self._urdf))

    def onion_labels(self, seg: np.ndarray | None = None) -> tuple[OnionLabel, ...]:
        """The onions in the world now (not those parked out of it), in line-up order, with
        their true class, position and whether each is in focus; with ``seg`` (H, W), the
        segmentation of a main-camera render, each visible one's box in that view."""
        self._require_client()
        boxes = {} if seg is None else boxes_from_segmentation(seg, [o.body for o in self._onions])
        out = []
        for o in self._onions:
            position = self.position(o.index)
            if position[2] <= _PARKED[2] / 2:
                continue
            box = boxes.get(o.body)
            out.append(OnionLabel(onion_id=o.index, blemished=bool(o.appearance.blemished),
                                  position=position, in_focus=o.index == self.focus,
                                  box=None if box is None else tuple(box[:4]),
                                  visible_pixels=0 if box is None else box[4]))
        return tuple(out)

    def _pedestal(self) -> int:
        half = [0.13, 0.13, ROBOT_BASE[2] / 2]
        vis = p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=[0.25, 0.25, 0.27, 1],
                                  physicsClientId=self.client)
        return p.createMultiBody(0, -1, vis, basePosition=[*ROBOT_BASE[:2], half[2]],
                                 physicsClientId=self.client)

    def _make_onions(self) -> list[_LineUpOnion]:
        onions = []
        lanes = np.random.default_rng(self._lanes_seq).uniform(*_LANES, len(self.lineup))
        with tempfile.TemporaryDirectory(prefix="station-onions-") as tmp:
            for i, look in enumerate(self.lineup):
                tex = onion_texture(look, 64, subtlety=self.difficulty.blemish_subtlety,
                                    one_sided=self.difficulty.one_sided_blemish)
                png = save_texture(tex, Path(tmp) / f"{i}.png")
                texture = p.loadTexture(str(png), physicsClientId=self.client)
                vis = p.createVisualShape(p.GEOM_SPHERE, radius=look.radius,
                                          rgbaColor=[1, 1, 1, 1], physicsClientId=self.client)
                body = p.createMultiBody(0, -1, vis, basePosition=list(_PARKED),
                                         physicsClientId=self.client)
                p.changeVisualShape(body, -1, textureUniqueId=texture,
                                    physicsClientId=self.client)
                if self._blemish_probe is not None:
                    self._blemish_probe.add(body, texture, look, 64,
                                            subtlety=self.difficulty.blemish_subtlety,
                                            one_sided=self.difficulty.one_sided_blemish)
                # queued so that at belt travel i * _SPACING it touches the raised gate (the
                # belt starts at travel -_SPACING)
                stop_x = _GATE_FACE - look.radius - 0.002
                pos = np.array([stop_x - (i + 1) * _SPACING, lanes[i], BELT_TOP + look.radius])
                onions.append(_LineUpOnion(i, body, look, pos))
        return onions

    # -- the world ---------------------------------------------------------------------------
    def _put(self, onion: _LineUpOnion, position: np.ndarray | None = None) -> None:
        """Show ``onion`` at ``position`` (its own by default) if it is on the belt or in the bin;
        park it out of the world if it is upstream of the belt or has ridden off its end."""
        if position is not None:
            onion.position = np.asarray(position, float).copy()
        x = onion.position[0]
        if onion.place in ("queued", "belt") and x > BELT_HALF_LENGTH - 0.05:
            onion.place = "gone"
        visible = onion.place != "gone" and (
            onion.place != "queued" or x >= -BELT_HALF_LENGTH + 0.05)
        p.resetBasePositionAndOrientation(
            onion.body, onion.position.tolist() if visible else list(_PARKED), [0, 0, 0, 1],
            physicsClientId=self.client)

    def _arrange_belt(self) -> None:
        for onion in self._onions:
            if onion.place in ("queued", "belt", "waiting"):
                self._put(onion)

    def _run_belt(self, distance: float) -> None:
        """Carry every onion on the belt ``distance`` m downstream (the gate holds none)."""
        self._travel += distance
        for onion in self._onions:
            if onion.place in ("queued", "belt"):
                onion.position[0] += distance
                self._put(onion)

    def position(self, index: int) -> np.ndarray:
        """World position (3,) of line-up onion ``index``, as the physics client has it."""
        body = self._onions[int(index)].body
        pos, _ = p.getBasePositionAndOrientation(body, physicsClientId=self._require_client())
        return np.array(pos)

    def place_of(self, index: int) -> str:
        """Where line-up onion ``index`` is: queued, waiting, held, belt, bin, tray or gone."""
        return self._onions[int(index)].place

    def perceived(self, index: int) -> Prediction | None:
        """The class the robot perceived for onion ``index`` (None if never inspected)."""
        return self._onions[int(index)].perceived

    @property
    def flange(self) -> np.ndarray:
        """The Sawyer's flange position (3,)."""
        self._require_client()
        return self.arm.end_effector()[0]

    @property
    def state(self) -> SortingState:
        """The MDP state read off the world (:func:`robot.state_map.state_of_world` with the
        flange targets :data:`ROBOT_TARGETS`); :data:`START_STATE` before the first claim."""
        self._require_client()
        if self.focus is None:
            return START_STATE
        onion = self._onions[self.focus]
        world = WorldSnapshot(
            hand=self.flange, focus=self.position(self.focus),
            held=self.arm.grasped == onion.body,
            prediction=Prediction.UNKNOWN if onion.perceived is None else onion.perceived,
        )
        return state_of_world(world, ROBOT_TARGETS)

    def target_errors(self) -> dict[Location, tuple[float, float]]:
        """IK accuracy at each flange target: ``location -> (position error m, angle error rad)``.

        The arm is left where it was.
        """
        self._require_client()
        start = self.arm.q
        errors = {}
        down = np.array(_down(0.0))
        for loc, target in ROBOT_TARGETS.items():
            self.arm.reset(self._solve(target))
            pos, orn = self.arm.end_effector()
            angle = 2 * np.arccos(min(1.0, abs(float(np.dot(orn, down)))))
            errors[loc] = (float(np.linalg.norm(pos - target)), float(angle))
        self.arm.reset(start)
        return errors

    def render(self, *, initial: bool = False) -> CameraImage:
        """The main camera's view now (with the difficulty's image effects).

        ``initial`` draws the effects' noise from a stream of its own, for the view before the
        first action: rendering it (to record the run from its start) never changes the
        renders after the actions.
        """
        image = render(self._require_client(), self.camera, self.lighting)
        if self.look is not None:
            image = replace(image, rgb=self.look.camera(image.rgb))
        if self.difficulty.is_clean:
            return image
        effects = self._initial_effects if initial else self.effects
        return CameraImage(rgb=effects.color(image.rgb, self._clock),
                           depth=effects.depth(image.depth), seg=image.seg)

    def render_inspection(self) -> CameraImage:
        """The inspection view now, as the classifier reads it: with the difficulty's image
        effects and, by chance, the gripper over part of the held onion."""
        image = render(self._require_client(), self.inspection, self.lighting,
                       cull=(self.arm.body,))
        if self.look is not None:
            image = replace(image, rgb=self.look.camera(image.rgb))
        if self.difficulty.is_clean:
            return image
        box = None
        if self.focus is not None:
            boxes = boxes_from_segmentation(image.seg, [self._onions[self.focus].body])
            box = next(iter(boxes.values()))[:4] if boxes else None
        rgb, covered = self.inspection_effects.hand_and_cover(image.rgb, box, _GRIPPER_RGB)
        return CameraImage(rgb=self.inspection_effects.color(rgb, self._clock), depth=image.depth,
                           seg=image.seg, covered=covered)

    def inspection_labels(self, image: CameraImage | None = None) -> list[InspectionLabel]:
        """The ground truth of each onion in the inspection view ``image`` (rendered now if
        None), for training perception on what the robot will see.

        Boxes are ``(x_min, y_min, x_max, y_max)`` pixels (exclusive max) from the
        segmentation. With ``label_blemishes`` each label counts the onion's pixels that show
        rot (:class:`robot.blemishes.BlemishProbe`, measured now: call it with the world as it
        was when ``image`` was rendered), leaving out those the gripper covers.
        """
        if image is None:
            image = render(self._require_client(), self.inspection, self.lighting)
        boxes = boxes_from_segmentation(image.seg, [o.body for o in self._onions])
        by_body = {o.body: o for o in self._onions}
        rot = ({} if self._blemish_probe is None else
               self._blemish_probe.rot_pixels(self.inspection, boxes, image.covered))
        return [InspectionLabel(tuple(b[:4]), by_body[body].appearance.blemished, b[4],
                                rot.get(body)) for body, b in boxes.items()]

    # -- motion primitives -------------------------------------------------------------------
    def _solve(self, target: np.ndarray, orientation: tuple[float, ...] | None = None,
               seed: np.ndarray | None = None) -> np.ndarray:
        """Joint positions (7,) putting the flange at ``target`` (3,), pointing down (turned by
        the quaternion ``orientation`` if given).

        The IK starts from ``seed`` (7,), by default the canonical configuration above the pick
        spot, so the answer does not depend on where the arm happens to be (IK started from a
        folded or turned wrist can stall at a joint limit). The arm ends where it was.
        """
        start = self.arm.q
        self.arm.reset(self._q_rest if seed is None else seed)
        q = self.arm.inverse_kinematics(np.asarray(target, float),
                                        _down(0.0) if orientation is None else orientation)
        self.arm.reset(start)
        return q

    def _move(self, target: np.ndarray, steps: int | None = None, *,
              orientation: tuple[float, ...] | None = None,
              seed: np.ndarray | None = None) -> float:
        """Move the flange to ``target`` (3,) in ``steps`` physics steps, then let it settle
        (short corrective motions, at most :data:`_MAX_SETTLE`) to within :data:`_SETTLE_TOL`;
        returns the final position error (m). ``orientation`` and ``seed`` as in
        :meth:`_solve`."""
        target = np.asarray(target, float)
        q = self._solve(target, orientation, seed)
        self.arm.move_to_joints(q, steps=steps or self.move_steps)
        err = float(np.linalg.norm(self.flange - target))
        for _ in range(_MAX_SETTLE):
            if err <= _SETTLE_TOL:
                break
            self.arm.move_to_joints(q, steps=_SETTLE_STEPS)
            err = float(np.linalg.norm(self.flange - target))
        if err > 0.02:
            logger.warning("the Sawyer stopped %.3f m from %s", err,
                           np.round(target, 3).tolist())
        return err

    def _above(self, point: np.ndarray) -> np.ndarray:
        return np.array([point[0], point[1], ROBOT_TARGETS[Location.CONVEYOR][2]])

    def _claim(self) -> list[float]:
        if self.n_claimed >= len(self._onions):
            raise RuntimeError(
                f"the line-up is exhausted: all {len(self._onions)} onions were claimed"
            )
        self.gate.set(True)
        onion = self._onions[self.n_claimed]
        self._run_belt(self.n_claimed * _SPACING - self._travel)
        onion.place = "waiting"
        self.focus, self.n_claimed = onion.index, self.n_claimed + 1
        return []

    def _pick(self, onion: _LineUpOnion) -> list[float]:
        errs = []
        grip = onion.position + np.array([0.0, 0.0, onion.appearance.radius + _GAP])
        if np.linalg.norm(self.flange - self._above(grip)) > 0.01:
            errs.append(self._move(self._above(grip)))
        errs.append(self._move(grip, self.move_steps // 2))
        self.arm.grasp(onion.body, kinematic=True)
        onion.place = "held"
        self.gate.set(False)
        errs.append(self._move(self._above(grip), self.move_steps // 2))
        errs.append(self._move(ROBOT_TARGETS[Location.HOVER]))
        return errs

    def _classify(self, onion: _LineUpOnion, views: list[np.ndarray],
                  view_p: list[float | None] | None = None
                  ) -> tuple[Prediction | None, float | None, tuple[float | None, ...]]:
        """The classifier's answer on ``views`` (None if it abstains: UNKNOWN), with the
        probability that the onion is blemished and that of each view, where it gives them;
        from a sequential classifier's ``view_p`` (one per view) when given."""
        if self.classify == GROUND_TRUTH:
            truth = Prediction.BAD if onion.appearance.blemished else Prediction.GOOD
            return truth, float(onion.appearance.blemished), ()
        raw = self.classify(views) if view_p is None else self.classify.verdict(view_p)
        p_bad, per_view = None, ()
        if hasattr(raw, "prediction"):
            p_bad = getattr(raw, "p_blemished", None)
            per_view = tuple(getattr(raw, "view_p_blemished", ()))
            raw = raw.prediction
        try:
            answer = Prediction(int(raw))
        except (TypeError, ValueError):
            raise ValueError(f"classify must return a Prediction (GOOD, BAD, or UNKNOWN to "
                             f"abstain) or a verdict with one; got {raw!r}") from None
        return (None if answer == Prediction.UNKNOWN else answer,
                None if p_bad is None else float(p_bad), per_view)

    def _inspect(self, onion: _LineUpOnion
                 ) -> tuple[list[float], list[CameraImage], list[float | None] | None]:
        """Hold the onion up to the inspection camera and show it from every side.

        The onion arrives at the inspection pose, then the wrist turns (and tilts) it through
        :attr:`poses` about its own centre, rendering the inspection camera at each, and
        brings it back to the inspection pose. A :class:`SequentialClassifier` reads each view
        as it comes, and with :attr:`stop_when_settled` the showing ends once the call is
        settled. Returns the motions' errors, the views (none if the onion was inspected
        before: it is only held up again) and, from a sequential classifier, each view's
        probability (else None).
        """
        target = ROBOT_TARGETS[Location.FACE]
        errs = [self._move(target)]
        if onion.perceived is not None:
            return errs, [], None
        sequential = isinstance(self.classify, SequentialClassifier)
        centre = self.position(onion.index)
        views: list[CameraImage] = []
        view_p: list[float | None] = []
        self.last_labels = []
        for k, (yaw, tilt) in enumerate(self.poses):
            if k:
                turn = _down(yaw, tilt)
                errs.append(self._move(self.arm.flange_holding_at(centre, turn),
                                       self.move_steps // 2, orientation=turn,
                                       seed=self.arm.q))
            views.append(self.render_inspection())
            if self.label_blemishes:
                self.last_labels.append(self.inspection_labels(views[-1]))
            if sequential:
                view_p.extend(self.classify.view_probabilities([views[-1].rgb]))
                if self.stop_when_settled and self.classify.settled(
                        view_p, len(self.poses) - k - 1):
                    break
        if len(views) > 1:
            errs.append(self._move(target, self.move_steps // 2, seed=self.arm.q))
        return errs, views, view_p if sequential else None

    def _place_on_conveyor(self, onion: _LineUpOnion) -> list[float]:
        inspected = onion.perceived is not None
        r = onion.appearance.radius
        # an inspected onion goes downstream of the gate and rides away; an uninspected one
        # stays in focus: it goes back to the gate, which rises again
        x = _PLACE_X if inspected else _GATE_FACE - r - 0.002
        rest = np.array([x, onion.position[1], BELT_TOP + r])
        grip = rest + np.array([0.0, 0.0, r + _GAP])
        errs = [self._move(self._above(grip)), self._move(grip, self.move_steps // 2)]
        self.arm.release()
        onion.place = "belt" if inspected else "waiting"
        self.gate.set(not inspected)
        self._put(onion, rest)
        errs.append(self._move(self._above(grip), self.move_steps // 2))
        errs.append(self._move(ROBOT_TARGETS[Location.CONVEYOR], self.move_steps // 2))
        return errs

    def _place_in_bin(self, onion: _LineUpOnion) -> list[float]:
        errs = [self._move(ROBOT_TARGETS[Location.BIN])]
        self.arm.release()
        onion.place = "bin"
        slot, layer = self._in_bin % _BIN_SLOTS, min(self._in_bin // _BIN_SLOTS, _BIN_LAYERS - 1)
        self._in_bin += 1
        grid = np.array([slot % 3 - 1, slot // 3 - 1], float) * 0.09
        jitter = self._scene_rng.uniform(-0.015, 0.015, 2)
        floor = BIN_TOP - 0.29  # top of the bin's floor
        self._put(onion, np.array([BIN_CENTER[0] + grid[0] + jitter[0],
                                   BIN_CENTER[1] + grid[1] + jitter[1],
                                   floor + onion.appearance.radius + 0.07 * layer]))
        return errs

    def defer(self) -> int:
        """Set the onion in focus aside on the check tray for a person to sort (the robot was
        not sure enough of its policy's action); nothing is then in focus, and the policy goes
        on from :data:`START_STATE`. Returns the onion's line-up index.

        Raises
        ------
        RuntimeError
            If no onion is in focus.
        """
        self._require_client()
        if self.focus is None:
            raise RuntimeError("no onion is in focus to defer")
        onion = self._onions[self.focus]
        self._clock += STEP_DURATION_S
        if onion.place != "held":
            self._pick(onion)
        self._move(ROBOT_TARGETS[Location.HOVER])
        self.arm.release()
        onion.place = "tray"
        self._put(onion, _TRAY + np.array([0.09 * (self._on_tray % 6), 0.09 * (self._on_tray // 6),
                                           onion.appearance.radius]))
        self._on_tray += 1
        self.gate.set(True)
        self._move(ROBOT_TARGETS[Location.CONVEYOR], self.move_steps // 2)
        self.focus = None
        return onion.index

    def step(self, action: SortAction | int) -> StationStep:
        """Execute ``action`` and check that the world reached the MDP's next state.

        Raises
        ------
        ValueError
            If ``action`` is not a :class:`SortAction`, or the classifier's answer is not a
            :class:`Prediction`.
        RuntimeError
            If the world does not show ``next_state(s, a, blemished=<perceived class>)``, or a
            CLAIM finds the line-up exhausted.
        """
        self._require_client()
        try:
            a = SortAction(int(action))
        except (TypeError, ValueError):
            raise ValueError(
                f"action must be a SortAction in [0, {len(SortAction)}); got {action!r}"
            ) from None
        s = self.state
        self._clock += STEP_DURATION_S
        applies = next_state(s, a, blemished=False) != s or next_state(s, a, blemished=True) != s
        errs: list[float] = []
        perceived, views, p_bad, per_view = None, (), None, ()
        if applies:
            onion = None if self.focus is None else self._onions[self.focus]
            if a == SortAction.CLAIM:
                errs = self._claim()
            elif a == SortAction.PICK:
                errs = self._pick(onion)
            elif a == SortAction.INSPECT:
                errs, shown, view_p = self._inspect(onion)
                if shown:
                    views = tuple(v.rgb for v in shown)
                    perceived, p_bad, per_view = self._classify(onion, list(views), view_p)
                    if perceived is None:
                        logger.warning("the classifier abstained on onion %d in all %d views; "
                                       "it counts as GOOD", onion.index, len(views))
                        perceived = Prediction.GOOD
                    onion.perceived = perceived
                    self.last_views = shown
            elif a == SortAction.PLACE_ON_CONVEYOR:
                errs = self._place_on_conveyor(onion)
            else:
                errs = self._place_in_bin(onion)
        focus = None if self.focus is None else self._onions[self.focus]
        seen_bad = focus is not None and focus.perceived == Prediction.BAD
        expected = next_state(s, a, blemished=seen_bad)
        seen = self.state
        if seen != expected:
            raise RuntimeError(f"after {a.name} in {s} the world shows {seen}; the MDP says "
                               f"{expected}")
        logger.debug("%s: %s -> %s", a.name, s, seen)
        return StationStep(
            state=s, action=a, next_state=seen, onion=self.focus, perceived=perceived,
            inspection=views[0] if views else None,
            image=self.render() if self.render_every_step else None,
            q=self.arm.q, reach_error=max(errs, default=0.0), views=views, p_blemished=p_bad,
            view_p_blemished=per_view,
        )


def robot_inspection_views(n_onions: int, seed: int | np.random.SeedSequence,
                           difficulty: Difficulty | str = DIFFICULTY_LEVELS["clean"],
                           inspection_views: int = INSPECTION_VIEWS,
                           camera: CameraSpec = ROBOT_INSPECTION_CAMERA,
                           randomize_look: bool = False,
                           ) -> Iterator[tuple[int, int, np.ndarray, list]]:
    """The Sawyer's inspection views of a line-up, with their ground-truth boxes.

    The expert's greedy policy runs the line-up, the robot showing each onion from
    ``inspection_views`` sides (:func:`inspection_poses`) to ``camera``, and a classifier that
    knows the truth. Yields ``(onion index, view index, rgb (h, w, 3) uint8, labels)``, the
    labels :class:`InspectionLabel` with the rot each view shows; ``difficulty`` and
    ``randomize_look`` as for :class:`SawyerStation`.
    """
    from irl.domains.onion_sorting import encode_state, onion_sorting

    actions = onion_sorting().expert_policy().argmax(axis=1)
    with SawyerStation(GROUND_TRUTH, n_onions=n_onions, n_blemished=n_onions // 2, seed=seed,
                       difficulty=difficulty, inspection=camera,
                       inspection_views=inspection_views, label_blemishes=True,
                       randomize_look=randomize_look) as station:
        for _ in range(n_onions * 6):
            if all(station.place_of(i) in ("bin", "belt", "gone") for i in range(n_onions)):
                break
            done = station.step(int(actions[encode_state(station.state)]))
            if done.views:
                for k, (image, labels) in enumerate(zip(station.last_views, station.last_labels,
                                                        strict=True)):
                    yield done.onion, k, image.rgb, labels
