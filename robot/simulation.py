"""A recorded sorting session: the human sorter acts on the expert's policy in the PyBullet world.

At each abstract step ``t`` the sorter, in MDP state ``s_t``, draws ``a_t ~ pi[s_t, :]``,
performs it as a smooth motion, and the world reaches
``s_{t+1} = next_state(s_t, a_t, blemished=<the physical onion's class>)``. The step is rendered
``frames_per_step`` times; its first frame shows ``s_t`` at rest. After every step the state read
off the world (:func:`robot.state_map.state_of_world`) is checked against ``s_{t+1}``.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field, replace

import numpy as np
import pybullet as p

from irl.demonstrations import StepTruth
from irl.domains.onion_sorting import (
    N_ACTIONS,
    N_STATES,
    Location,
    Prediction,
    SortAction,
    SortingState,
    decode_state,
    encode_state,
    next_state,
)
from robot.avatar import HAND_RADIUS, HumanSorter, path_point
from robot.camera import (
    CameraSpec,
    Lighting,
    boxes_from_segmentation,
    occluded_fraction,
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
from robot.labels import OnionLabel
from robot.look import Look, draw_look, look_rng
from robot.occluder import PasserBy, occlusion_schedule
from robot.scene import Onion, OnionPool, StopGate, build_workcell, connect
from robot.state_map import HAND_TARGETS, PICK_SPOT, WorldSnapshot, state_of_world
from robot.world import WorldFrame, WorldProbe, WorldState, camera_pose

__all__ = ["INSPECTION_CAMERA", "SessionConfig", "SortingSession", "expert_model"]

#: How far the sorter turns the onion in hand (about the vertical, radians) while lifting it
#: to the face to inspect it, as a person looks at more than one side.
_INSPECT_TURN = np.pi

logger = logging.getLogger(__name__)

INSPECTION_CAMERA = CameraSpec(
    width=160, height=120, fov_deg=40.0, eye=(0.02, 0.08, 1.50), target=(0.02, 0.32, 1.45),
    frame_id="inspection",
)
"""A close view of the place in front of the sorter's face where onions are inspected."""


@dataclass(frozen=True)
class SessionConfig:
    """Everything that shapes one session besides its seed.

    Attributes
    ----------
    n_steps : int
        Abstract steps (sorter actions) per session.
    occlusion : float
        Probability that the passer-by crosses the view during a step.
    frames_per_step : int
        Frames rendered per step (the first shows the state at rest).
    step_duration_s : float
        Simulated seconds per step.
    belt_speed : float
        Belt speed in m/s.
    n_onions : int
        Onions in the pool riding the belt.
    blemish_rate : float
        Probability that an onion is blemished.
    texture_size : int
        Side of each onion texture in pixels.
    camera, inspection : CameraSpec
        The main RGB-D camera facing the sorter, and the inspection view (rendered with every
        frame).
    difficulty : Difficulty or str
        Perception difficulty (:mod:`robot.difficulty`): a :class:`Difficulty` or the name of
        one of :data:`robot.difficulty.DIFFICULTY_LEVELS`; ``"clean"`` renders today's world.
    label_blemishes : bool
        Measure the rot each onion shows in the inspection view (one more render of it per
        frame; :attr:`robot.labels.OnionLabel.rot_pixels`), for datasets.
    randomize_look : bool
        Draw the world's look from the session's seed (:mod:`robot.look`: light, surface
        colours, the cameras' exposure and white balance), for training data; off, the world
        renders exactly as without it. Independent of ``difficulty``.
    """

    n_steps: int = 20
    occlusion: float = 0.2
    frames_per_step: int = 3
    step_duration_s: float = 2.0
    belt_speed: float = 0.03
    n_onions: int = 8
    blemish_rate: float = 0.5
    texture_size: int = 64
    camera: CameraSpec = field(default_factory=CameraSpec)
    inspection: CameraSpec = INSPECTION_CAMERA
    difficulty: Difficulty = DIFFICULTY_LEVELS["clean"]
    label_blemishes: bool = False
    randomize_look: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "difficulty", resolve_difficulty(self.difficulty))
        if self.n_steps < 1:
            raise ValueError(f"n_steps must be >= 1; got {self.n_steps}")
        if not 0.0 <= self.occlusion <= 1.0:
            raise ValueError(f"occlusion must be in [0, 1]; got {self.occlusion}")
        if self.frames_per_step < 1:
            raise ValueError(f"frames_per_step must be >= 1; got {self.frames_per_step}")
        if self.step_duration_s <= 0:
            raise ValueError(f"step_duration_s must be > 0; got {self.step_duration_s}")
        if not 0.0 <= self.blemish_rate <= 1.0:
            raise ValueError(f"blemish_rate must be in [0, 1]; got {self.blemish_rate}")

    def to_dict(self) -> dict:
        """A JSON-ready dict of the configuration."""
        return asdict(self)


def expert_model(blemish_rate: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """The Boltzmann expert ``pi[s, a]`` (48, 5) and initial distribution (48,) of the domain."""
    from irl.domains.onion_sorting import onion_sorting

    domain = onion_sorting(blemish_rate=blemish_rate)
    return domain.expert_policy(), np.asarray(domain.mdp.initial, float)


def _grip_offset(onion: Onion) -> np.ndarray:
    """Onion centre relative to the hand holding it (3,): in front of and below the palm."""
    return -np.array([0.0, 0.6, 0.8]) * (HAND_RADIUS + 0.6 * onion.appearance.radius)


class SortingSession:
    """One session in its own headless PyBullet client; use as a context manager.

    Parameters
    ----------
    config : SessionConfig
    policy : ndarray of shape (48, 5)
        The sorter's policy ``pi[s, a]`` (rows sum to 1).
    initial : ndarray of shape (48,)
        Distribution of the first state.
    seed : int or numpy.random.SeedSequence
        Seeds the scene's appearance, the policy's draws and the passer-by independently.

    Attributes
    ----------
    steps : list of StepTruth
        The steps taken so far.
    occluded : ndarray of shape (n_steps,)
        The passer-by's schedule (full crossings: the steps labelled occluded).
    partial : ndarray of shape (n_steps,)
        Steps at which a passer-by walks past the edge of the view only (the difficulty's
        ``partial_occlusion``); they stay labelled unoccluded.
    lighting : Lighting
    """

    def __init__(self, config: SessionConfig, policy: np.ndarray, initial: np.ndarray,
                 seed: int | np.random.SeedSequence) -> None:
        policy, initial = np.asarray(policy, float), np.asarray(initial, float)
        if policy.shape != (N_STATES, N_ACTIONS) or not np.allclose(policy.sum(1), 1.0):
            raise ValueError(
                f"policy must be pi[s, a] of shape ({N_STATES}, {N_ACTIONS}) with rows summing "
                f"to 1; got shape {policy.shape}"
            )
        if initial.shape != (N_STATES,) or not np.isclose(initial.sum(), 1.0):
            raise ValueError(f"initial must be a distribution of shape ({N_STATES},); got "
                             f"shape {initial.shape}")
        self.config, self.policy, self.initial = config, policy, initial
        seq = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
        scene_seq, policy_seq, occl_seq, walker_seq = seq.spawn(4)
        self._scene_rng = np.random.default_rng(scene_seq)
        self._policy_rng = np.random.default_rng(policy_seq)
        self.occluded = occlusion_schedule(config.n_steps, config.occlusion,
                                           np.random.default_rng(occl_seq))
        self._walker_rng = np.random.default_rng(walker_seq)
        # the difficulty draws from a stream of its own: the clean world's draws are unchanged
        self._difficulty_rng = difficulty_rng(seq)
        self._look_rng = look_rng(seq)  # and so does the look
        d = config.difficulty
        self.partial = np.zeros(config.n_steps, bool)
        if d.partial_occlusion:
            self.partial = ~self.occluded & (self._difficulty_rng.random(config.n_steps)
                                             < d.partial_occlusion)
        self.steps: list[StepTruth] = []
        self.client: int | None = None

    # -- lifecycle ---------------------------------------------------------------------------
    def __enter__(self) -> SortingSession:
        self.client = connect()
        rng = self._scene_rng
        self.lighting: Lighting = sample_lighting(rng)
        self.workcell = build_workcell(self.client, rng)
        self.look: Look | None = None
        if self.config.randomize_look:
            self.look = draw_look(self._look_rng)
            self.lighting = self.look.lighting
            self.look.paint(self.client, self.workcell)
        d = self.config.difficulty
        self.pool = OnionPool(self.client, self.config.n_onions, self.config.blemish_rate, rng,
                              texture_size=self.config.texture_size,
                              blemish_subtlety=d.blemish_subtlety,
                              one_sided_blemish=d.one_sided_blemish)
        self.effects = ImageEffects(d, self._difficulty_rng)
        self._blemish_probe = None
        if self.config.label_blemishes:
            from robot.blemishes import BlemishProbe

            self._blemish_probe = BlemishProbe(self.client)
            for o in self.pool.onions:
                self._blemish_probe.add(o.body, self.pool.textures[o.body], o.appearance,
                                        self.config.texture_size,
                                        subtlety=d.blemish_subtlety,
                                        one_sided=d.one_sided_blemish)
        self.sorter = HumanSorter(self.client, rng)
        self.gate = StopGate(self.client)
        cam = self.config.camera
        self.walker = PasserBy(self.client, self._walker_rng, cam.eye, cam.target)
        self.focus: Onion | None = None
        self._probe = WorldProbe(self.client, self._named_bodies(), classes={
            f"onions/{o.onion_id}": int(o.blemished) for o in self.pool.onions})
        self._cameras = {spec.frame_id: camera_pose(spec)
                         for spec in (self.config.camera, self.config.inspection)}
        return self

    def __exit__(self, *exc) -> None:
        if self.client is not None:
            p.disconnect(physicsClientId=self.client)
            self.client = None

    # -- the world ---------------------------------------------------------------------------
    def _named_bodies(self) -> dict[str, int]:
        """Every body of the world by its shape name (:class:`robot.world.ShapeState`)."""
        bodies = {f"workcell/{name}": body for name, body in self.workcell.items()}
        bodies["gate"] = self.gate.body
        bodies.update({f"sorter/{part}": body for part, body in zip(
            ("torso", "legs", "head", "left_arm", "upper_arm", "forearm", "hand"),
            self.sorter.body_ids, strict=True)})
        bodies.update({f"passer_by/{part}": body for part, body in zip(
            ("coat", "head", "legs"), self.walker.body_ids, strict=True)})
        bodies.update({f"onions/{o.onion_id}": o.body for o in self.pool.onions})
        return bodies

    def world_state(self) -> WorldState:
        """The world now, for 3D logging: every body as a primitive (onions with their true
        class) and the cameras' optical frames; a sorter's world has no robot."""
        if self.client is None:
            raise RuntimeError("SortingSession must be entered (`with SortingSession(...)`)")
        return WorldState(shapes=self._probe.shapes(), cameras=dict(self._cameras))

    def _held_position(self, onion: Onion) -> np.ndarray:
        return self.sorter.hand_position + _grip_offset(onion)

    def _pinned(self, state: SortingState) -> bool:
        return state.onion == Location.CONVEYOR and state.prediction == Prediction.UNKNOWN

    def _claim(self) -> Onion:
        """The next onion arriving at the sorter's station (nearest upstream of the pick spot)."""
        on_belt = [o for o in self.pool.onions if o.place == "belt" and o is not self.focus]
        upstream = [o for o in on_belt if PICK_SPOT[0] - 0.7 <= o.position[0] <= PICK_SPOT[0]]
        if upstream:
            return max(upstream, key=lambda o: o.position[0])
        onion = min(on_belt, key=lambda o: abs(o.position[0] - PICK_SPOT[0]))
        self.pool.put_on_belt(onion, x=PICK_SPOT[0] - 0.3)
        return onion

    def _setup(self, state: SortingState) -> None:
        """Arrange the world to show ``state`` at rest."""
        self.sorter.set_hand(HAND_TARGETS[state.end_effector])
        wanted = {Prediction.GOOD: False, Prediction.BAD: True}.get(state.prediction)
        candidates = [o for o in self.pool.onions if wanted is None or o.blemished == wanted]
        self.focus = candidates[0] if candidates else self.pool.onions[0]
        if state.onion in (Location.HOVER, Location.FACE):
            if state.end_effector != state.onion:
                raise ValueError(f"initial state {state} holds an onion away from the hand")
            self.focus.place = "held"
            self.pool.move(self.focus, self._held_position(self.focus))
        elif state.onion == Location.BIN:
            self.pool.drop_in_bin(self.focus)
        else:
            self.pool.put_on_belt(self.focus, x=PICK_SPOT[0], y=PICK_SPOT[1])

    def _plan(self, s: SortingState, a: SortAction, s_next: SortingState) -> np.ndarray:
        """Hand waypoints (K, 3) of action ``a`` from ``s`` to ``s_next``."""
        hand = self.sorter.hand_position.copy()
        if s_next == s:
            return hand[None]
        if a == SortAction.PICK:
            top = self.focus.position - _grip_offset(self.focus)
            return np.stack([hand, top, HAND_TARGETS[Location.HOVER]])
        if a == SortAction.CLAIM:
            return hand[None]
        return np.stack([hand, HAND_TARGETS[s_next.end_effector]])

    def _render(self, index: int, label: StepTruth, phase: int, time_s: float,
                with_inspection: bool) -> WorldFrame:
        image = render(self.client, self.config.camera, self.lighting)
        onions = self._onion_labels(image.seg)
        inspection, inspection_onions = None, ()
        if with_inspection:
            close = render(self.client, self.config.inspection, self.lighting)
            inspection_onions = tuple(o for o in self._onion_labels(close.seg) if o.box)
            focus = [o.box for o in inspection_onions if o.in_focus]
            rgb, covered = self.effects.hand_and_cover(close.rgb, focus[0] if focus else None,
                                                       self.sorter.skin)
            inspection = self.effects.color(self._camera(rgb), time_s)
            if self._blemish_probe is not None:
                bodies = {o.onion_id: self.pool.onions[o.onion_id].body
                          for o in inspection_onions}
                rot = self._blemish_probe.rot_pixels(self.config.inspection,
                                                     bodies.values(), covered)
                inspection_onions = tuple(replace(o, rot_pixels=rot[bodies[
                    o.onion_id]]) for o in inspection_onions)
        return WorldFrame(
            index=index, step=label, phase=phase, time_s=time_s,
            color=self.effects.color(self._camera(image.rgb), time_s, moving=phase > 0),
            depth=self.effects.depth(image.depth), onions=onions,
            occluded_fraction=occluded_fraction(image.seg, self.walker.body_ids),
            inspection=inspection, inspection_onions=inspection_onions,
            world=self.world_state(),
        )

    def _camera(self, rgb: np.ndarray) -> np.ndarray:
        """``rgb`` through the look's camera (exposure, white balance); as it is without one."""
        return rgb if self.look is None else self.look.camera(rgb)

    def _onion_labels(self, seg: np.ndarray) -> tuple[OnionLabel, ...]:
        """Every onion of the pool, with its box in the view whose segmentation is ``seg``."""
        boxes = boxes_from_segmentation(seg, self.pool.body_ids)
        return tuple(
            OnionLabel(
                onion_id=o.onion_id, blemished=o.blemished, position=o.position.copy(),
                in_focus=o is self.focus,
                box=boxes[o.body][:4] if o.body in boxes else None,
                visible_pixels=boxes[o.body][4] if o.body in boxes else 0,
            )
            for o in self.pool.onions
        )

    # -- the run -----------------------------------------------------------------------------
    def frames(self) -> Iterator[WorldFrame]:
        """Run the session, yielding its frames in order, each with a snapshot of the world
        (:class:`robot.world.WorldFrame`); :attr:`steps` fills as it goes."""
        if self.client is None:
            raise RuntimeError("SortingSession must be entered (`with SortingSession(...)`)")
        cfg = self.config
        dt = cfg.step_duration_s / cfg.frames_per_step
        s = decode_state(int(self._policy_rng.choice(N_STATES, p=self.initial)))
        self._held_turn = 0.0  # how far the sorter has turned the onion in hand (radians)
        self._setup(s)
        index = 0
        for t in range(cfg.n_steps):
            s_idx = encode_state(s)
            a = SortAction(int(self._policy_rng.choice(N_ACTIONS, p=self.policy[s_idx])))
            if a == SortAction.CLAIM and next_state(s, a, False) != s:
                self.focus = self._claim()
            s_next = next_state(s, a, blemished=self.focus.blemished)
            label = StepTruth(step=t, state=s_idx, action=int(a),
                              next_state=encode_state(s_next), occluded=bool(self.occluded[t]))
            self.steps.append(label)
            waypoints = self._plan(s, a, s_next)
            crossing = bool(self.occluded[t] or self.partial[t])
            if self.occluded[t]:
                self.walker.start_crossing()
            elif self.partial[t]:
                cam = cfg.camera
                self.walker.start_crossing(
                    partial=True, rng=self._difficulty_rng,
                    tan_half_fov=np.tan(np.deg2rad(cam.fov_deg) / 2) * cam.width / cam.height)
            for k in range(cfg.frames_per_step + 1):
                phase = k / cfg.frames_per_step
                if k > 0:  # the belt moves between frames; the focus onion waits at the gate
                    stop_x = (self.focus.position[0] if a == SortAction.PICK else PICK_SPOT[0])
                    stop = (self.focus, stop_x) if self._pinned(s) else None
                    self.pool.advance(cfg.belt_speed * dt, stop=stop)
                self.sorter.set_hand(path_point(waypoints, phase))
                # the gate is up while a claimed onion waits: it rises as the sorter claims
                # one and drops as the sorter reaches for it
                self.gate.set(self._pinned(s if k == 0 else s_next))
                if a == SortAction.PICK and s_next != s and phase >= 0.5:
                    self.focus.place = "held"
                if a == SortAction.INSPECT and s_next != s:
                    self._held_turn = _INSPECT_TURN * phase  # turned in hand on the way up
                if self.focus.place == "held":
                    self.pool.move(self.focus, self._held_position(self.focus),
                                   yaw=self._held_turn)
                if k == cfg.frames_per_step:
                    break  # the step's end is the next step's first frame
                self.walker.walk((k + 0.5) / cfg.frames_per_step if crossing else None)
                yield self._render(index, label, k, (t + phase) * cfg.step_duration_s,
                                   with_inspection=True)
                index += 1
            self._finish_step(a, s_next)
            if self.focus.place != "held":
                self._held_turn = 0.0
            s = s_next
        self.walker.walk(None)

    def _finish_step(self, a: SortAction, s_next: SortingState) -> None:
        """Release the onion where the action put it and check the world shows ``s_next``."""
        if self.focus.place == "held" and s_next.onion == Location.CONVEYOR:
            self.pool.put_on_belt(self.focus, x=PICK_SPOT[0], y=PICK_SPOT[1])
        elif self.focus.place == "held" and s_next.onion == Location.BIN:
            self.pool.drop_in_bin(self.focus)
        world = WorldSnapshot(hand=self.sorter.hand_position, focus=self.focus.position,
                              held=self.focus.place == "held", prediction=s_next.prediction)
        seen = state_of_world(world)
        if seen != s_next:
            raise RuntimeError(f"after {a.name} the world shows {seen}, the MDP says {s_next}")
