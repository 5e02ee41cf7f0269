"""The Sawyer sorting station: the robot executes sorting actions on a line-up of onions.

The workcell is the human sessions' (:func:`robot.scene.build_workcell`, the :class:`StopGate`,
the main :class:`~robot.camera.CameraSpec`), with the Sawyer standing where the sorter stood,
facing the belt. It inspects at the sorter's inspection spot, through a camera of its own
(:data:`ROBOT_INSPECTION_CAMERA`: the spot as the sorter's camera sees it, at twice the
resolution, as a real cell would fit its inspection station with a sharper camera than the one
that watches the person; the difficulty's image effects apply to it as to every camera).
Each :class:`~irl.domains.onion_sorting.SortAction` is a motion primitive of the Sawyer
(:mod:`robot.primitives`) on the station's line-up and belt (:mod:`robot.belt`), seen through
its cameras (:mod:`robot.station_cameras`). The station is a :class:`robot.cell.SortingCell`:
the sorting loop (:class:`robot.cell.SortingRun`) drives it, and on INSPECT reads the views it
shows into the onion's call (:class:`robot.cell.ViewReader`; a classifier may abstain only if no
view shows the onion). :meth:`SawyerStation.step` is one action of that loop with the station's
own classifier.

Each onion's inspection views are the same whichever policy sorts the line-up: the arm is
exactly at each view's pose, holding the onion as its pick aimed to (:mod:`robot.primitives`);
each view's noise and gripper come from a stream of the view's own
(:func:`robot.difficulty.view_rng`); and its light drifts to the onion's slot on the line
(:func:`inspection_time`), not to how long the policy took to get there. A line-up recorded
with one policy therefore stands in for the arm with any other (:mod:`robot.replay`).

For 3D logging, :meth:`SawyerStation.world_state` snapshots the work cell, the gate, the onions
on the belt, held or in the bin (with their classes), both cameras and the Sawyer's joints
(:mod:`robot.world`); :func:`station_robot` describes the Sawyer as it stands here before a
station exists (a logger draws it from its URDF).

An action that the MDP says does nothing in the current state (``next_state(s, a) == s``) does
nothing physically. After every action the state read off the world (:meth:`SawyerStation.state`)
must equal ``next_state(s, a, blemished=<the class the classifier perceived>)``: the prediction
factor is what the robot *perceived*, so perception errors propagate exactly as in the MDP.

Positions are world metres, shape (3,); joint vectors have shape (7,).
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import pybullet as p

from irl.domains.onion_sorting import (
    Location,
    Prediction,
    SortAction,
    SortingState,
    encode_state,
    onion_sorting,
)
from robot.assets import sawyer_urdf
from robot.belt import Belt, LineUpOnion, in_world, make_lineup
from robot.blemishes import BlemishProbe
from robot.camera import CameraImage, CameraSpec, boxes_from_segmentation, sample_lighting
from robot.cell import START_STATE, Read, ViewReader, take_action
from robot.classifier import GROUND_TRUTH, Classifier
from robot.difficulty import DIFFICULTY_LEVELS, Difficulty, resolve_difficulty
from robot.inspection_poses import INSPECTION_VIEWS, inspection_poses
from robot.labels import OnionLabel
from robot.look import draw_look, look_rng
from robot.primitives import ROBOT_TARGETS, MotionPrimitives
from robot.sawyer import Sawyer
from robot.scene import StopGate, build_workcell, connect
from robot.state_map import WorldSnapshot, state_of_world
from robot.station_cameras import ROBOT_INSPECTION_CAMERA, InspectionLabel, StationCameras
from robot.tally import Fate
from robot.world import Pose, RobotState, WorldProbe, WorldState, camera_pose, robot_state

__all__ = [
    "INSPECTION_VIEWS",
    "ROBOT_BASE",
    "ROBOT_BASE_YAW",
    "SAWYER_JOINTS",
    "START_STATE",
    "STEP_DURATION_S",
    "SawyerStation",
    "StationStep",
    "inspection_poses",
    "inspection_time",
    "robot_inspection_views",
    "station_robot",
]

logger = logging.getLogger(__name__)


ROBOT_BASE = np.array([0.30, 0.70, 0.90])
"""Where the Sawyer's base stands: behind the sorter's stance, on a pedestal."""
ROBOT_BASE_YAW = -np.pi / 2
"""The base faces -y, across the belt (as the sorter did)."""
SAWYER_JOINTS = tuple(f"right_j{k}" for k in range(7))
"""The Sawyer's joints in the order of a joint vector ``q`` (7,) (its URDF's names)."""
STEP_DURATION_S = 2.0
"""The station's clock per action (s): action ``t`` runs from ``t * STEP_DURATION_S`` to
``(t + 1) * STEP_DURATION_S`` (the difficulty's lighting drift follows it)."""

#: Actions a sorting cycle takes an onion: claim, pick, inspect, place (the expert's).
_CYCLE = 4
#: Where each fate of :class:`robot.cell.SortingCell` is among an onion's places.
_FATES: dict[str, Fate] = {"bin": "bin", "tray": "tray", "belt": "line", "gone": "line"}


def inspection_time(index: int) -> float:
    """The clock (s) the light of onion ``index``'s inspection views drifts to: the end of
    action ``4 * index + 2``, when a cycle of four actions an onion (claim, pick, inspect,
    place) inspects it. The light drifts along the line-up, whatever a policy's pace."""
    return (_CYCLE * int(index) + 3) * STEP_DURATION_S


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
        (h, w, 3) uint8; :mod:`robot.classifier`): GOOD, BAD, or UNKNOWN to abstain (an onion
        it never classifies counts as GOOD); ``"ground-truth"`` perceives each onion's true
        class (the views are still taken).
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
        With a :class:`~robot.classifier.SequentialClassifier`, :meth:`step` stops showing an
        onion as soon as its call can no longer change (under ``noisy-or``, a view that shows
        rot settles a blemish at once): the call all its views would give, from fewer. False:
        always take every view.
    label_blemishes : bool
        Measure the rot each inspection view shows, for :attr:`last_labels` (one more render
        per view; for datasets).
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
    reader : ViewReader
        How :meth:`step` reads an onion's views (``classify``, ``inspection_views``,
        ``stop_when_settled``).
    lineup : tuple of OnionAppearance
        The onions in the order they arrive.
    blemished : ndarray of shape (n_onions,)
        Their true classes.
    focus : int or None
        Line-up index of the onion in focus (the last one claimed).
    last_views : list of CameraImage
        The last inspection's views as rendered.
    last_labels : list of list of InspectionLabel
        With ``label_blemishes``, the ground truth of each of them.
    lighting : Lighting
    arm, gate, belt, cameras, motions
        Its parts, once entered: :class:`~robot.sawyer.Sawyer`, :class:`~robot.scene.StopGate`,
        :class:`~robot.belt.Belt`, :class:`~robot.station_cameras.StationCameras`,
        :class:`~robot.primitives.MotionPrimitives`.
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
        self.reader = ViewReader(classify, max_views=inspection_views,
                                 stop_when_settled=stop_when_settled)
        if isinstance(move_steps, bool) or not isinstance(move_steps, int | np.integer) \
                or move_steps < 2:
            raise ValueError(f"move_steps must be an int >= 2; got {move_steps!r}")
        self.poses = inspection_poses(inspection_views)
        self.stop_when_settled = bool(stop_when_settled)
        self.label_blemishes = bool(label_blemishes)
        self.randomize_look = bool(randomize_look)
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
        self._errs: list[float] = []  # the arm's reach errors in the last action

    # -- lifecycle ---------------------------------------------------------------------------
    def __enter__(self) -> SawyerStation:
        self.client = connect()
        scene_rng = np.random.default_rng(self._scene_seq)  # the same world on every entry
        try:
            self.lighting = sample_lighting(scene_rng)
            self.workcell = build_workcell(self.client, scene_rng)
            self.gate = StopGate(self.client)
            self.workcell["pedestal"] = _pedestal(self.client)
            look = None
            if self.randomize_look:  # from a stream of its own: the line-up is unchanged
                look = draw_look(look_rng(self._difficulty_seq))
                self.lighting = look.lighting
                look.paint(self.client, self.workcell)
            self.arm = Sawyer(self.client, base_position=ROBOT_BASE, base_yaw=ROBOT_BASE_YAW)
            self.arm.rest = self.arm.inverse_kinematics(ROBOT_TARGETS[Location.CONVEYOR])
            self.arm.reset(self.arm.rest)
            probe = BlemishProbe(self.client) if self.label_blemishes else None
            self.belt = Belt(self.client, self.lineup, lanes=self._lanes_seq,
                             difficulty=self.difficulty, rng=scene_rng, probe=probe)
            bodies = {f"workcell/{name}": body for name, body in self.workcell.items()}
            bodies["gate"] = self.gate.body
            bodies.update({f"onions/{o.index}": o.body for o in self.belt.onions})
            self._probe = WorldProbe(self.client, bodies, classes={
                f"onions/{o.index}": int(o.appearance.blemished) for o in self.belt.onions})
            self._urdf = sawyer_urdf()
        except BaseException:
            self.__exit__(None, None, None)
            raise
        self.cameras = StationCameras(self.client, self.camera, self.inspection, self.lighting,
                                      look, self.difficulty, self._difficulty_seq,
                                      cull=(self.arm.body,), probe=probe)
        self.motions = MotionPrimitives(self.arm, self.belt, self.gate, self.move_steps)
        self.focus = None
        self.last_views: list[CameraImage] = []
        self.last_labels: list[list[InspectionLabel]] = []
        self.belt.arrange()
        return self

    def __exit__(self, *exc) -> None:
        if self.client is not None:
            p.disconnect(physicsClientId=self.client)
            self.client = None

    def _require_client(self) -> int:
        if self.client is None:
            raise RuntimeError("SawyerStation must be entered (`with SawyerStation(...)`)")
        return self.client

    # -- the cell now ------------------------------------------------------------------------
    @property
    def state(self) -> SortingState:
        """The MDP state read off the world (:func:`robot.state_map.state_of_world` with the
        flange targets :data:`robot.primitives.ROBOT_TARGETS`); :data:`START_STATE` before the
        first claim."""
        self._require_client()
        if self.focus is None:
            return START_STATE
        onion = self.belt.onions[self.focus]
        world = WorldSnapshot(
            hand=self.flange, focus=self.position(self.focus),
            held=self.arm.grasped == onion.body,
            prediction=Prediction.UNKNOWN if onion.perceived is None else onion.perceived,
        )
        return state_of_world(world, ROBOT_TARGETS)

    @property
    def flange(self) -> np.ndarray:
        """The Sawyer's flange position (3,)."""
        self._require_client()
        return self.arm.end_effector()[0]

    def position(self, index: int) -> np.ndarray:
        """World position (3,) of line-up onion ``index``, as the physics client has it."""
        self._require_client()
        return self.belt.position(index)

    def place_of(self, index: int) -> str:
        """Where line-up onion ``index`` is: queued, waiting, held, belt, bin, tray or gone."""
        return self.belt.onions[int(index)].place

    def perceived(self, index: int) -> Prediction | None:
        """The class the robot perceived for onion ``index`` (None if never inspected)."""
        return self.belt.onions[int(index)].perceived

    def render(self, *, initial: bool = False) -> CameraImage:
        """The main camera's view now (:meth:`StationCameras.render
        <robot.station_cameras.StationCameras.render>`; ``initial`` for the view before the
        first action)."""
        self._require_client()
        return self.cameras.render(initial=initial)

    def world_state(self) -> WorldState:
        """The world now, for 3D logging (:class:`robot.world.WorldState`): the work cell (its
        pedestal too), the gate and the onions that are in the world (on the belt, held, in the
        bin; not those parked out of it), each onion with its true class; the optical frames of
        the main camera and the inspection view; the Sawyer's base and joint positions."""
        client = self._require_client()
        shapes = tuple(s for s in self._probe.shapes() if in_world(s.pose.position))
        cameras = {spec.frame_id: camera_pose(spec) for spec in (self.camera, self.inspection)}
        return WorldState(shapes=shapes, cameras=cameras,
                          robot=robot_state(client, self.arm.body, self.arm.joints,
                                            self._urdf))

    def onion_labels(self, seg: np.ndarray | None = None) -> tuple[OnionLabel, ...]:
        """The onions in the world now (not those parked out of it), in line-up order, with
        their true class, position and whether each is in focus; with ``seg`` (H, W), the
        segmentation of a main-camera render, each visible one's box in that view."""
        self._require_client()
        onions = self.belt.onions
        boxes = {} if seg is None else boxes_from_segmentation(seg, [o.body for o in onions])
        out = []
        for o in onions:
            position = self.position(o.index)
            if not in_world(position):
                continue
            box = boxes.get(o.body)
            out.append(OnionLabel(onion_id=o.index, blemished=bool(o.appearance.blemished),
                                  position=position, in_focus=o.index == self.focus,
                                  box=None if box is None else tuple(box[:4]),
                                  visible_pixels=0 if box is None else box[4]))
        return tuple(out)

    def fate(self, index: int) -> Fate | None:
        """What became of onion ``index``: ``"bin"``, ``"line"`` (set back on the belt after
        inspection, or ridden away), ``"tray"``, or None while undecided."""
        return _FATES.get(self.place_of(index))

    # -- acting ------------------------------------------------------------------------------
    def step(self, action: SortAction | int) -> StationStep:
        """Execute ``action`` with the station's own classifier (:attr:`reader`), as the sorting
        loop does (:func:`robot.cell.take_action`), and check that the world reached the MDP's
        next state.

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
        self._errs = []
        done = take_action(self, action, self.reader, self.blemished)
        return StationStep(
            state=done.state, action=done.action, next_state=done.next_state, onion=done.onion,
            perceived=done.perceived, inspection=done.views[0] if done.views else None,
            image=self.render() if self.render_every_step else None, q=self.arm.q,
            reach_error=max(self._errs, default=0.0), views=done.views,
            p_blemished=done.p_blemished, view_p_blemished=done.view_p_blemished,
        )

    def execute(self, action: SortAction | int) -> None:
        """Carry out CLAIM, PICK, PLACE_ON_CONVEYOR or PLACE_IN_BIN, each a motion primitive
        (:mod:`robot.primitives`), as :class:`robot.cell.SortingCell` asks; the loop sends only
        actions that change the state. The station's clock advances by
        :data:`STEP_DURATION_S`.

        Raises
        ------
        ValueError
            If ``action`` is INSPECT (:meth:`inspect`) or not a :class:`SortAction`.
        RuntimeError
            If a CLAIM finds the line-up exhausted, or another action finds no onion in focus.
        """
        self._require_client()
        a = SortAction(int(action))
        if a == SortAction.INSPECT:
            raise ValueError("INSPECT reads the views: call inspect(read)")
        if a != SortAction.CLAIM and self.focus is None:
            raise RuntimeError(f"no onion is in focus to {a.name}")
        self.cameras.time_s += STEP_DURATION_S
        onion = None if self.focus is None else self.belt.onions[self.focus]
        if a == SortAction.CLAIM:
            self.focus = self.motions.claim().index
        elif a == SortAction.PICK:
            self._errs = self.motions.pick(onion)
        elif a == SortAction.PLACE_ON_CONVEYOR:
            self._errs = self.motions.place_on_conveyor(onion)
        else:
            self._errs = self.motions.place_in_bin(onion)

    def inspect(self, read: Read) -> None:
        """INSPECT: hold the onion in focus up to the inspection camera; the first time, show
        it from every side (:meth:`MotionPrimitives.show
        <robot.primitives.MotionPrimitives.show>`), rendering each view as ``read`` asks for it
        (:attr:`last_views`), and keep the call ``read`` returns. The station's clock advances
        by :data:`STEP_DURATION_S`; the views are lit as at :func:`inspection_time`.

        Raises
        ------
        RuntimeError
            If no onion is in focus.
        """
        onion = self._step_on_focus("inspect")
        self._errs = self.motions.hold_up()
        if onion.perceived is not None:
            return  # only held up again
        shown = self._views(onion)
        try:
            call = read(shown)
        finally:
            shown.close()
        onion.perceived = Prediction(int(call))

    def _step_on_focus(self, doing: str) -> LineUpOnion:
        """The onion in focus, for a step that acts on it (``doing``, named by the error): the
        station's clock advances by :data:`STEP_DURATION_S`.

        Raises
        ------
        RuntimeError
            If no onion is in focus.
        """
        self._require_client()
        if self.focus is None:
            raise RuntimeError(f"no onion is in focus to {doing}")
        self.cameras.time_s += STEP_DURATION_S
        return self.belt.onions[self.focus]

    def _views(self, onion: LineUpOnion) -> Iterator[np.ndarray]:
        """The held onion's inspection views (h, w, 3) uint8, each rendered as it is asked for
        with the arm at its pose, kept in :attr:`last_views` (and, labelling, its ground truth
        in :attr:`last_labels`)."""
        self.last_views, self.last_labels = [], []
        poses = self.motions.show(onion, self.poses, self._errs)
        try:
            for k in poses:
                image = self.cameras.render_inspection(
                    onion.body, view=(onion.index, k), time_s=inspection_time(onion.index))
                self.last_views.append(image)
                if self.label_blemishes:
                    self.last_labels.append(self.cameras.inspection_labels(image,
                                                                           self.belt.onions))
                yield image.rgb
        finally:
            poses.close()

    def defer(self) -> int:
        """Set the onion in focus aside on the check tray for a person to sort (the robot was
        not sure enough of its policy's action); nothing is then in focus, and the policy goes
        on from :data:`START_STATE`. Returns the onion's line-up index.

        Raises
        ------
        RuntimeError
            If no onion is in focus.
        """
        onion = self._step_on_focus("defer")
        self.motions.set_aside(onion)
        self.focus = None
        return onion.index


def _pedestal(client: int) -> int:
    """The Sawyer's pedestal, under :data:`ROBOT_BASE`."""
    half = [0.13, 0.13, ROBOT_BASE[2] / 2]
    vis = p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=[0.25, 0.25, 0.27, 1],
                              physicsClientId=client)
    return p.createMultiBody(0, -1, vis, basePosition=[*ROBOT_BASE[:2], half[2]],
                             physicsClientId=client)


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
