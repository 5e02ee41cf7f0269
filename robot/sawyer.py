"""The Sawyer arm from its official URDF: inverse kinematics, joint motion, a suction grasp.

Joint vectors ``q`` have shape (7,) (``right_j0`` .. ``right_j6``); positions are world metres,
shape (3,). The suction cup is modelled at the flange of ``right_l6``: :meth:`Sawyer.grasp`
welds an object to it with a fixed constraint, which the physics keeps while the arm moves
under position control (:meth:`Sawyer.move_to`). Static (mass-0) bodies, such as the kinematic
onions of :mod:`robot.scene`, cannot hang from a constraint (the weld would pin the arm to
them): ``grasp(body, kinematic=True)`` instead makes the body follow the flange, its pose reset
to the flange's after every physics step.
"""

from __future__ import annotations

import logging

import numpy as np
import pybullet as p

from robot.assets import sawyer_urdf

__all__ = ["Sawyer", "flange_down", "orientation_angle"]

logger = logging.getLogger(__name__)

#: A comfortable configuration: elbow up, flange pointing down.
HOME = np.array([0.0, -1.18, 0.0, 2.18, 0.0, 0.57, 3.3161])
_DOWN = p.getQuaternionFromEuler([np.pi, 0.0, 0.0])
_SETTLE_TOL, _SETTLE_STEPS, _MAX_SETTLE = 0.005, 20, 8  # corrective motions after a reach
_ORIENTATION_TOL = 0.01
"""How far (radians) a :meth:`Sawyer.solve` solution may turn the flange from the pose asked
for and still be kept among several starts."""


def orientation_angle(a, b) -> float:
    """The angle (radians) between two orientations, quaternions (x, y, z, w)."""
    return 2.0 * float(np.arccos(min(1.0, abs(float(np.dot(a, b))))))


def flange_down(yaw: float, tilt: float = 0.0) -> tuple[float, ...]:
    """Quaternion (x, y, z, w) of the flange pointing down, turned by ``yaw`` about z, then
    tilted by ``tilt`` about x so that what hangs from it swings towards -y."""
    down = p.getQuaternionFromEuler([np.pi, 0.0, -yaw])
    if not tilt:
        return tuple(down)
    turn = p.getQuaternionFromEuler([-tilt, 0.0, 0.0])
    return tuple(p.multiplyTransforms([0, 0, 0], turn, [0, 0, 0], down)[1])


class Sawyer:
    """A fixed-base Sawyer in physics client ``client``.

    Parameters
    ----------
    client : int
        PyBullet physics client id.
    base_position : array of shape (3,)
        Where the arm's base stands.
    base_yaw : float
        Rotation of the base about z, radians.

    Raises
    ------
    robot.assets.AssetNotFoundError
        If the robosuite asset package (and with it the URDF) is not installed.

    Attributes
    ----------
    rest : ndarray of shape (7,)
        The configuration :meth:`solve` starts its IK from (:data:`HOME` until set).
    """

    def __init__(self, client: int, base_position=(0.0, 0.0, 0.0), base_yaw: float = 0.0):
        self.client = client
        self.body = p.loadURDF(
            str(sawyer_urdf()), basePosition=list(base_position),
            baseOrientation=p.getQuaternionFromEuler([0.0, 0.0, base_yaw]),
            useFixedBase=True, physicsClientId=client,
        )
        self.joints = [j for j in range(p.getNumJoints(self.body, physicsClientId=client))
                       if p.getJointInfo(self.body, j, physicsClientId=client)[2]
                       == p.JOINT_REVOLUTE]
        if len(self.joints) != 7:
            raise RuntimeError(f"the Sawyer URDF must have 7 revolute joints; got "
                               f"{len(self.joints)}")
        self.end_link = self.joints[-1]
        info = [p.getJointInfo(self.body, j, physicsClientId=client) for j in self.joints]
        self.lower = np.array([i[8] for i in info])
        self.upper = np.array([i[9] for i in info])
        self._grasp: int | None = None
        self._carried: tuple[list[float], list[float]] | None = None  # flange -> body pose
        self.grasped: int | None = None
        self.rest = HOME
        self.goal: np.ndarray | None = None  # the last reach's joint solution
        self.reset(HOME)

    def reset(self, q: np.ndarray) -> None:
        """Teleport the joints to ``q`` (7,) (no dynamics)."""
        for j, qj in zip(self.joints, np.asarray(q, float), strict=True):
            p.resetJointState(self.body, j, qj, 0.0, physicsClientId=self.client)

    @property
    def q(self) -> np.ndarray:
        """Joint positions, shape (7,)."""
        return np.array([s[0] for s in p.getJointStates(self.body, self.joints,
                                                        physicsClientId=self.client)])

    def end_effector(self) -> tuple[np.ndarray, np.ndarray]:
        """Flange position (3,) and orientation quaternion (4,) in the world."""
        state = p.getLinkState(self.body, self.end_link, computeForwardKinematics=True,
                               physicsClientId=self.client)
        return np.array(state[4]), np.array(state[5])

    def inverse_kinematics(self, position, orientation=_DOWN, *, max_iter: int = 20,
                           tol: float = 1e-3) -> np.ndarray:
        """Joint positions (7,) putting the flange at ``position`` (3,) with ``orientation``.

        Runs PyBullet's damped-least-squares IK, re-linearising from each solution (clipped to
        the joint limits), up to ``max_iter`` times or until the position error is below ``tol``
        metres; warns if it does not converge (the target may be out of reach). The arm ends
        where it started.
        """
        start = self.q
        q = start
        err = np.inf
        for _ in range(max_iter):
            sol = p.calculateInverseKinematics(
                self.body, self.end_link, list(position), list(orientation),
                maxNumIterations=200, residualThreshold=1e-6, physicsClientId=self.client,
            )
            q = np.clip(np.array(sol[:7]), self.lower, self.upper)
            self.reset(q)
            err = float(np.linalg.norm(self.end_effector()[0] - np.asarray(position)))
            if err < tol:
                break
        else:
            logger.warning("Sawyer IK did not converge: %.4f m from %s after %d iterations",
                           err, np.round(position, 3).tolist(), max_iter)
        self.reset(start)
        return q

    def solve(self, position, orientation=None, seed: np.ndarray | None = None) -> np.ndarray:
        """Joint positions (7,) putting the flange at ``position`` (3,), pointing down (turned by
        the quaternion ``orientation`` if given).

        The IK starts from ``seed``, by default :attr:`rest`, so the answer does not depend on
        where the arm happens to be (IK started from a folded or turned wrist can stall at a
        joint limit). ``seed`` may hold several starts, shape (n, 7): each is tried in turn, and
        the first solution within 1 mm and :data:`_ORIENTATION_TOL` of the pose is kept (else
        the closest). The arm ends where it was.
        """
        start = self.q
        position = np.asarray(position, float)
        want = flange_down(0.0) if orientation is None else orientation
        seeds = [self.rest] if seed is None else np.atleast_2d(np.asarray(seed, float))
        best, best_err = None, np.inf
        for s in seeds:
            self.reset(s)
            q = self.inverse_kinematics(position, want)
            self.reset(q)
            pos, orn = self.end_effector()
            err = max(float(np.linalg.norm(pos - position)) / 1e-3,
                      orientation_angle(orn, want) / _ORIENTATION_TOL)
            if err < best_err:
                best, best_err = q, err
            if err <= 1.0:
                break
        self.reset(start)
        return best

    def wrist_turns(self, q: np.ndarray, yaw: float) -> np.ndarray:
        """Starts for :meth:`solve` (n, 7) turning the flange of configuration ``q`` (7,) by
        ``yaw`` radians about its own axis (:func:`flange_down`'s ``yaw``): ``q`` with the last
        joint, which turns the flange about that axis, at each of ``q[6] + yaw`` and its
        turns by whole circles within the joint's limits, the smallest turn first. An IK
        started from ``q`` itself turns the wrist by the shortest way, into its limit if that
        way is out of reach.
        """
        q = np.asarray(q, float)
        turns = yaw + 2 * np.pi * np.arange(-2, 3)
        ends = q[6] + turns
        keep = (ends >= self.lower[6]) & (ends <= self.upper[6])
        if not keep.any():  # the joint turns through more than a full circle: never here
            raise ValueError(f"no turn of the wrist by {yaw!r} rad (whole circles apart) is "
                             f"within its limits from {q[6]!r}")
        order = np.argsort(np.abs(turns[keep]), kind="stable")
        seeds = np.repeat(q[None], int(keep.sum()), axis=0)
        seeds[:, 6] = ends[keep][order]
        return seeds

    def reach(self, position, steps: int, *, orientation=None,
              seed: np.ndarray | None = None) -> float:
        """Move the flange to ``position`` (3,) in ``steps`` physics steps, then let it settle
        (short corrective motions, at most :data:`_MAX_SETTLE`) to within :data:`_SETTLE_TOL`;
        returns the final position error (m), and warns past 2 cm. ``orientation`` and ``seed``
        as in :meth:`solve`."""
        position = np.asarray(position, float)
        q = self.solve(position, orientation, seed)
        self.goal = q
        self.move_to_joints(q, steps=steps)
        err = float(np.linalg.norm(self.end_effector()[0] - position))
        for _ in range(_MAX_SETTLE):
            if err <= _SETTLE_TOL:
                break
            self.move_to_joints(q, steps=_SETTLE_STEPS)
            err = float(np.linalg.norm(self.end_effector()[0] - position))
        if err > 0.02:
            logger.warning("the Sawyer stopped %.3f m from %s", err,
                           np.round(position, 3).tolist())
        return err

    def snap(self) -> None:
        """Put the joints exactly at the last :meth:`reach`'s solution (what the motion ended
        within :data:`_SETTLE_TOL` of), bringing a kinematically held body along: a pose the
        arm repeats whatever it came from, as a real arm does to a tenth of a millimetre.

        Raises
        ------
        RuntimeError
            If the arm has reached for nothing yet.
        """
        if self.goal is None:
            raise RuntimeError("the Sawyer has reached for nothing yet")
        self.reset(self.goal)
        self._carry()

    def move_to(self, position, orientation=_DOWN, *, steps: int = 240) -> float:
        """Drive the arm to a pose under position control, stepping the physics ``steps`` times.

        The joint targets follow a minimum-jerk interpolation from the current configuration to
        the IK solution. Returns the final flange position error in metres.
        """
        self.move_to_joints(self.inverse_kinematics(position, orientation), steps=steps)
        return float(np.linalg.norm(self.end_effector()[0] - np.asarray(position)))

    def move_to_joints(self, q: np.ndarray, *, steps: int = 240) -> None:
        """Drive the joints to ``q`` (7,) under position control, stepping the physics ``steps``
        times; the joint targets follow a minimum-jerk interpolation from the current
        configuration."""
        from robot.avatar import min_jerk

        q0, q1 = self.q, np.asarray(q, float)
        for k in range(1, steps + 1):
            target = q0 + float(min_jerk(k / steps)) * (q1 - q0)
            p.setJointMotorControlArray(
                self.body, self.joints, p.POSITION_CONTROL, targetPositions=target.tolist(),
                forces=[200.0] * 7, physicsClientId=self.client)
            p.stepSimulation(physicsClientId=self.client)
            self._carry()

    def grasp(self, body: int, *, kinematic: bool = False,
              flange: tuple[np.ndarray, tuple[float, ...]] | None = None) -> None:
        """Suction: hold ``body`` at the flange where it is now.

        By default a fixed constraint welds it to the flange (for dynamic bodies); with
        ``kinematic=True`` the body follows the flange rigidly, its pose reset after every
        physics step of :meth:`move_to_joints` (for static, mass-0 bodies). ``flange``, a
        position (3,) and quaternion, holds the body as if the flange were there (the grasp
        the motion aimed at, rather than where it stopped within its tolerance).
        """
        if self.grasped is not None:
            raise RuntimeError(f"already holding body {self.grasped}; release it first")
        ee_pos, ee_orn = self.end_effector() if flange is None else \
            (np.asarray(flange[0], float), np.asarray(flange[1], float))
        obj_pos, obj_orn = p.getBasePositionAndOrientation(body, physicsClientId=self.client)
        inv_pos, inv_orn = p.invertTransform(ee_pos.tolist(), ee_orn.tolist())
        rel_pos, rel_orn = p.multiplyTransforms(inv_pos, inv_orn, obj_pos, obj_orn)
        if kinematic:
            self._carried = (list(rel_pos), list(rel_orn))
            self.grasped = body
            return
        self._grasp = p.createConstraint(
            self.body, self.end_link, body, -1, p.JOINT_FIXED, [0, 0, 0],
            parentFramePosition=rel_pos, childFramePosition=[0, 0, 0],
            parentFrameOrientation=rel_orn, physicsClientId=self.client,
        )
        p.changeConstraint(self._grasp, maxForce=500.0, physicsClientId=self.client)
        self.grasped = body

    def _carry(self) -> None:
        """Put a kinematically held body where the flange holds it."""
        if self._carried is None or self.grasped is None:
            return
        ee_pos, ee_orn = self.end_effector()
        pos, orn = p.multiplyTransforms(ee_pos.tolist(), ee_orn.tolist(), *self._carried)
        p.resetBasePositionAndOrientation(self.grasped, pos, orn, physicsClientId=self.client)

    def flange_holding_at(self, position, orientation) -> np.ndarray:
        """Where the flange (3,) must be, turned to ``orientation`` (quaternion), for the body
        it holds kinematically to be at ``position`` (3,).

        Raises
        ------
        RuntimeError
            If the arm holds nothing kinematically.
        """
        if self._carried is None:
            raise RuntimeError("the Sawyer holds no body kinematically")
        rel_pos, _ = self._carried
        offset, _ = p.multiplyTransforms([0, 0, 0], list(orientation), rel_pos, [0, 0, 0, 1])
        return np.asarray(position, float) - np.array(offset)

    def release(self) -> None:
        """Switch the suction off."""
        if self._grasp is not None:
            p.removeConstraint(self._grasp, physicsClientId=self.client)
        self._grasp, self._carried, self.grasped = None, None, None
