"""A ROS 2 arm as an onion-sorting cell (robot.cell.SortingCell)."""

import numpy as np
import rclpy
from builtin_interfaces.msg import Duration
from control_msgs.action import FollowJointTrajectory
from cv_bridge import CvBridge
from rclpy.action import ActionClient
from rclpy.node import Node
from sensor_msgs.msg import Image
from std_srvs.srv import SetBool, Trigger
from trajectory_msgs.msg import JointTrajectoryPoint

from irl.domains.onion_sorting import Location, Prediction, SortAction, SortingState
from robot.cell import START_STATE

JOINTS = [f"joint_{k}" for k in range(1, 8)]
#: Joint positions (rad) taught with the pendant: above the pick spot, at it, hovering, at the
#: inspection camera, setting down downstream, over the bin, over the check tray.
POSES = {
    "conveyor": [0.0, -0.60, 0.0, 1.90, 0.0, 1.10, 0.0],
    "pick": [0.0, -0.35, 0.0, 2.05, 0.0, 0.80, 0.0],
    "hover": [0.35, -0.80, 0.0, 1.70, 0.0, 1.00, 0.0],
    "face": [0.80, -0.90, 0.0, 1.30, 0.0, 0.70, 0.0],
    "place": [-0.30, -0.40, 0.0, 2.00, 0.0, 0.85, 0.0],
    "bin": [1.40, -0.70, 0.0, 1.60, 0.0, 1.00, 0.0],
    "tray": [1.75, -0.70, 0.0, 1.60, 0.0, 1.00, 0.0],
}
#: The wrist's turns (rad) from "face" at which the camera sees each side of the onion.
SIDES = (0.0, 1.57, 3.14, 4.71)


class Ros2Arm(Node):
    """The lab's arm as a sorting cell: it keeps where the onion and the gripper are, as each
    motion leaves them, and the call the loop read for each inspected onion."""

    def __init__(self) -> None:
        super().__init__("onion_sorter")
        self._trajectory = ActionClient(self, FollowJointTrajectory,
                                        "/arm_controller/follow_joint_trajectory")
        self._suction = self.create_client(SetBool, "/gripper/suction")
        self._conveyor = self.create_client(Trigger, "/conveyor/next_onion")
        self._bridge, self._image = CvBridge(), None
        self.create_subscription(Image, "/inspection_camera/image_raw", self._on_image, 1)
        self._focus, self._claimed = None, 0
        self._onion, self._hand = Location.CONVEYOR, Location.CONVEYOR
        self._calls, self._fates = {}, {}

    # -- what the loop reads --------------------------------------------------------------
    @property
    def state(self) -> SortingState:
        if self._focus is None:
            return START_STATE
        return SortingState(self._onion, self._hand,
                            self._calls.get(self._focus, Prediction.UNKNOWN))

    @property
    def focus(self) -> int | None:
        return self._focus

    def fate(self, index: int) -> str | None:
        return self._fates.get(index)

    # -- what the loop asks ---------------------------------------------------------------
    def execute(self, action: SortAction) -> None:
        if action == SortAction.CLAIM:
            self._call(self._conveyor, Trigger.Request())
            self._focus, self._claimed = self._claimed, self._claimed + 1
            self._onion = Location.CONVEYOR
        elif action == SortAction.PICK:
            self._pick()
        elif action == SortAction.PLACE_ON_CONVEYOR:
            inspected = self._focus in self._calls
            self._move("place" if inspected else "pick")  # unseen: back where it was
            self._suck(False)
            self._move("conveyor")
            if inspected:
                self._fates[self._focus] = "line"
            self._onion = self._hand = Location.CONVEYOR
        elif action == SortAction.PLACE_IN_BIN:
            self._move("bin")
            self._suck(False)
            self._fates[self._focus] = "bin"
            self._onion = self._hand = Location.BIN

    def inspect(self, read) -> None:
        self._move("face")
        self._onion = self._hand = Location.FACE
        if self._focus not in self._calls:
            self._calls[self._focus] = read(self._sides())
            self._move("face")

    def defer(self) -> int:
        onion = self._focus
        if self._onion == Location.CONVEYOR:
            self._pick()
        self._move("tray")
        self._suck(False)
        self._move("conveyor")
        self._fates[onion] = "tray"
        self._focus, self._hand = None, Location.CONVEYOR
        return onion

    # -- the arm --------------------------------------------------------------------------
    def _pick(self) -> None:
        self._move("pick")
        self._suck(True)
        self._move("hover")
        self._onion = self._hand = Location.HOVER

    def _sides(self):
        """The held onion's views, one a side, as the loop asks for them."""
        for turn in SIDES:
            self._move("face", wrist=turn)
            yield self._grab()

    def _move(self, place: str, wrist: float = 0.0, seconds: int = 2) -> None:
        goal = FollowJointTrajectory.Goal()
        goal.trajectory.joint_names = JOINTS
        q = list(POSES[place])
        q[-1] += wrist
        goal.trajectory.points = [JointTrajectoryPoint(
            positions=q, time_from_start=Duration(sec=seconds))]
        handle = self._wait(self._trajectory.send_goal_async(goal))
        if not handle.accepted:
            raise RuntimeError(f"the arm refused the motion to {place}")
        self._wait(handle.get_result_async())

    def _suck(self, on: bool) -> None:
        self._call(self._suction, SetBool.Request(data=on))

    def _call(self, client, request):
        client.wait_for_service()
        return self._wait(client.call_async(request))

    def _wait(self, future):
        rclpy.spin_until_future_complete(self, future)
        return future.result()

    def _grab(self) -> np.ndarray:
        """The inspection camera's next image after the motion, (h, w, 3) uint8 RGB."""
        self._image = None
        while self._image is None:
            rclpy.spin_once(self, timeout_sec=0.1)
        return self._image

    def _on_image(self, msg: Image) -> None:
        self._image = self._bridge.imgmsg_to_cv2(msg, desired_encoding="rgb8")


def main() -> None:
    from onionsort.policy import SortingPolicy
    from recordings.labels.sorting_csv import tally_rows, write_tally
    from robot.cell import SortingRun, ViewReader

    rclpy.init()
    arm = Ros2Arm()
    policy = SortingPolicy.load("runs/learn/mmap-birl")
    reader = ViewReader(policy.inspection(models="runs/lab-models"), max_views=len(SIDES))
    run = SortingRun(arm, 20, reader, confidence=policy.confidence_table, defer_below=0.9)
    run.run(policy.actions)
    write_tally("runs/arm/tally.csv", tally_rows(0, run.tally.outcomes()))
    arm.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
