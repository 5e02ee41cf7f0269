"""The session format: topics, message schemas and the session metadata record.

One MCAP file per session, in two sides. The **sensor side** is complete on its own: it is all a
real work cell records, and all that perception and the learners read. The **ground-truth side**
is what a simulator adds for training, calibration and scoring; a session recorded from a camera
or imported from a video has none. Images use Foxglove's well-known protobuf schemas; the step
clock and ground truth use JSON messages with JSON-schema channels, each on its own topic. Every
message's ``log_time`` is the recording time in nanoseconds and its ``sequence`` the frame
index.

Sensor side (``/camera/depth`` and the inspection view only where the sensor has them):

=========================  ==========================  ==========================================
topic                      schema                      content
=========================  ==========================  ==========================================
/camera/color              foxglove.CompressedImage    main RGB camera, JPEG, every frame
/camera/depth              foxglove.RawImage           depth, 16UC1 millimetres, every frame
/camera/calibration        foxglove.CameraCalibration  pinhole K, P of the main camera
/step_clock                onionsort.StepClock         which step each frame belongs to, and its
                                                       phase (position) within the step
/inspection/color          foxglove.CompressedImage    inspection view, PNG, first frame of a step
/inspection/calibration    foxglove.CameraCalibration  pinhole K, P of the inspection view
/tf                        foxglove.FrameTransforms    ``world`` -> ``camera``, ``inspection``
                                                       (optical frames) and a robot's links
/joint_states              foxglove.JointStates        a robot's joint positions
/evaluation/decision       onionsort.Decision          a robot's run: the action it took at each
                                                       step, what it perceived, the onion's fate
=========================  ==========================  ==========================================

Ground-truth side (optional):

=========================  ==========================  ==========================================
topic                      schema                      content
=========================  ==========================  ==========================================
/ground_truth/state        onionsort.GroundTruthState  true MDP state of each frame
/ground_truth/action       onionsort.GroundTruthStep   (s_t, a_t, s_t+1, occluded), once a step
/ground_truth/boxes        onionsort.GroundTruthBoxes  boxes of visible onions (segmentation)
/ground_truth/annotations  foxglove.ImageAnnotations   the same boxes, drawable over /camera/color
/ground_truth/onions       onionsort.GroundTruthOnions  every onion's class and position
/scene                     foxglove.SceneUpdate        the world's bodies in 3D, onions coloured
                                                       by class
/evaluation/counts         onionsort.SortingCounts     a robot's run: running TP, FP, TN, FN,
                                                       precision and recall after each step
=========================  ==========================  ==========================================

Metadata records: ``onionsort.session`` (written first: format and version, ``sensors``
(``depth``, ``inspection``), ``ground_truth``, ``frames_per_step``, the ``task`` description,
seed, configuration, software version) and ``onionsort.session.end`` (written last: status,
frame and step counts).

``/tf`` is there where the cameras' poses are known (a simulated session), ``/joint_states``
(and a robot's links on ``/tf``) where the world has a robot, whose URDF the metadata record
``onionsort.robot`` names; :mod:`recordings.session.world` writes and reads the three 3D topics.
They are optional within version ``2``: a reader ignores what it does not know, and files without
them open as before. So are the two ``/evaluation/*`` topics of a session that records a robot's own
sorting run (``onionsort evaluate``; :data:`EVALUATION_JSON_SCHEMAS`), once per step (their
``sequence`` is the step number).

Versions: ``2`` added the step clock, made depth and ground truth optional and records which
sensors a session has. A version-``1`` file (always simulated, always with depth) has no step
clock; the reader takes the step and phase of each frame from ``/ground_truth/state`` instead.
"""

from __future__ import annotations

import json

__all__ = [
    "CLASS_COLORS",
    "CLASS_NAMES",
    "END_METADATA",
    "EVALUATION_JSON_SCHEMAS",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "JSON_SCHEMAS",
    "PERCEPTION_METADATA",
    "READABLE_VERSIONS",
    "ROBOT_METADATA",
    "SENSOR_JSON_SCHEMAS",
    "SESSION_METADATA",
    "PerceptionTopic",
    "Topic",
    "check_task",
    "json_schema_bytes",
    "task_of",
]

FORMAT_NAME = "onionsort-session"
FORMAT_VERSION = "2"
#: Versions this reader opens.
READABLE_VERSIONS = ("1", "2")
SESSION_METADATA = "onionsort.session"
END_METADATA = "onionsort.session.end"
#: Metadata record of a session whose world has a robot: its name, URDF, root link, joints.
ROBOT_METADATA = "onionsort.robot"
#: Metadata record of a perceived session: which models wrote its perception topics.
PERCEPTION_METADATA = "onionsort.perception"

#: Class ids of onions in box annotations.
CLASS_NAMES = {0: "good", 1: "blemished"}
#: Their display colours (RGB 0-255), for Foxglove annotations and Rerun alike.
CLASS_COLORS = {0: (40, 200, 60), 1: (230, 40, 40)}


class Topic:
    """Topic names of a session."""

    COLOR = "/camera/color"
    DEPTH = "/camera/depth"
    CALIBRATION = "/camera/calibration"
    STEP_CLOCK = "/step_clock"
    INSPECTION = "/inspection/color"
    INSPECTION_CALIBRATION = "/inspection/calibration"
    STATE = "/ground_truth/state"
    ACTION = "/ground_truth/action"
    BOXES = "/ground_truth/boxes"
    ANNOTATIONS = "/ground_truth/annotations"
    ONIONS = "/ground_truth/onions"
    #: The 3D side (:mod:`recordings.session.world`): transforms and joint states (sensor side), the
    #: simulated world's bodies (ground truth).
    TF = "/tf"
    JOINT_STATES = "/joint_states"
    SCENE = "/scene"
    #: A robot's own sorting run, once per step: its decisions (sensor side: what the robot
    #: did and perceived) and the running TP/FP/TN/FN (ground truth: they need true classes).
    DECISION = "/evaluation/decision"
    COUNTS = "/evaluation/counts"
    #: Every ground-truth topic: what stripping a session of its ground truth removes.
    GROUND_TRUTH = (STATE, ACTION, BOXES, ANNOTATIONS, ONIONS, SCENE, COUNTS)


class PerceptionTopic:
    """Topic names of perception output (:mod:`recordings.session.perception` writes them)."""

    STATE = "/perception/state"
    DETECTIONS = "/perception/detections"
    ANNOTATIONS = "/perception/annotations"
    INSPECTION = "/perception/inspection"
    ALL = (STATE, DETECTIONS, ANNOTATIONS, INSPECTION)


_INT = {"type": "integer"}
_NUM = {"type": "number"}
_STR = {"type": "string"}
_BOOL = {"type": "boolean"}

#: The sensor side's JSON topics.
SENSOR_JSON_SCHEMAS: dict[str, tuple[str, dict]] = {
    Topic.STEP_CLOCK: ("onionsort.StepClock", {
        "type": "object",
        "description": "Which abstract step a frame belongs to and its position in the step "
                       "(phase 0 shows the state at rest). Written by the recorder, or by the "
                       "segmentation of an imported video; never derived from ground truth.",
        "properties": {"frame": _INT, "step": _INT, "phase": _INT},
        "required": ["frame", "step", "phase"],
    }),
}

#: The ground-truth side's JSON topics.
JSON_SCHEMAS: dict[str, tuple[str, dict]] = {
    Topic.STATE: ("onionsort.GroundTruthState", {
        "type": "object",
        "description": "True onion-sorting MDP state shown in a frame "
                       "(irl.domains.onion_sorting encoding).",
        "properties": {
            "frame": _INT, "step": _INT, "phase": _INT, "time_s": _NUM, "state": _INT,
            "onion": _STR, "end_effector": _STR, "prediction": _STR, "action": _INT,
            "occluded": _BOOL, "occluded_fraction": _NUM,
        },
        "required": ["frame", "step", "state", "action", "occluded"],
    }),
    Topic.ACTION: ("onionsort.GroundTruthStep", {
        "type": "object",
        "description": "One abstract step: state, action taken, next state, whether occluded.",
        "properties": {
            "step": _INT, "frame": _INT, "state": _INT, "action": _INT, "action_name": _STR,
            "next_state": _INT, "occluded": _BOOL,
        },
        "required": ["step", "state", "action", "next_state", "occluded"],
    }),
    Topic.BOXES: ("onionsort.GroundTruthBoxes", {
        "type": "object",
        "description": "Boxes (pixels, exclusive max) of the visible onions, from segmentation.",
        "properties": {
            "frame": _INT,
            "boxes": {"type": "array", "items": {"type": "object", "properties": {
                "onion_id": _INT, "class_id": _INT, "label": _STR, "x_min": _INT,
                "y_min": _INT, "x_max": _INT, "y_max": _INT, "visible_pixels": _INT,
            }}},
        },
        "required": ["frame", "boxes"],
    }),
    Topic.ONIONS: ("onionsort.GroundTruthOnions", {
        "type": "object",
        "description": "Every onion's true class and world position (metres).",
        "properties": {
            "frame": _INT,
            "onions": {"type": "array", "items": {"type": "object", "properties": {
                "onion_id": _INT, "blemished": _BOOL, "in_focus": _BOOL,
                "position": {"type": "array", "items": _NUM},
            }}},
        },
        "required": ["frame", "onions"],
    }),
}


_INT_OR_NULL = {"type": ["integer", "null"]}
_STR_OR_NULL = {"type": ["string", "null"]}

#: The JSON topics of a robot's sorting run (optional; once per step, ``sequence`` = step).
EVALUATION_JSON_SCHEMAS: dict[str, tuple[str, dict]] = {
    Topic.DECISION: ("onionsort.Decision", {
        "type": "object",
        "description": "One step of a robot's sorting run: in state it took action and "
                       "reached next_state (flat indices of the session's task, with their "
                       "names); the onion in focus afterwards, the class the robot perceived "
                       "if this step inspected it (with the fused probability that it is "
                       "blemished and each view's, null where a view showed no onion), and the "
                       "onion's fate (bin or line) if this step decided it. What the robot "
                       "knows; no ground truth.",
        "properties": {
            "step": _INT, "frame": _INT, "state": _INT, "state_name": _STR, "action": _INT,
            "action_name": _STR, "next_state": _INT, "next_state_name": _STR,
            "onion": _INT_OR_NULL, "perceived": _STR_OR_NULL, "fate": _STR_OR_NULL,
            "p_blemished": _NUM,
            "view_p_blemished": {"type": "array", "items": {"type": ["number", "null"]}},
        },
        "required": ["step", "state", "action", "next_state"],
    }),
    Topic.COUNTS: ("onionsort.SortingCounts", {
        "type": "object",
        "description": "The running confusion counts of a robot's sorting run after a step, "
                       "blemished the positive class: tp blemished in the bin, fp good in the "
                       "bin, tn good left on the line, fn blemished left on the line; "
                       "precision tp/(tp+fp) and recall tp/(tp+fn), 0 where undefined; the "
                       "true class of the onion in focus.",
        "properties": {
            "step": _INT, "frame": _INT, "onion": _INT_OR_NULL,
            "blemished": {"type": ["boolean", "null"]}, "tp": _INT, "fp": _INT, "tn": _INT,
            "fn": _INT, "decided": _INT, "precision": _NUM, "recall": _NUM,
        },
        "required": ["step", "tp", "fp", "tn", "fn", "precision", "recall"],
    }),
}


def check_task(task, reserved: tuple[str, ...], where: str):
    """Refuse a task that is not a TaskDescription, or whose factor names would collide with
    the keys of the messages or records (``where``) that carry its factors by name."""
    from irl.domains.task import TaskDescription

    if not isinstance(task, TaskDescription):
        raise TypeError(f"task must be a TaskDescription; got {type(task).__name__}")
    clash = [f for f in task.factor_names if f in reserved]
    if clash:
        raise ValueError(f"task {task.name!r}: factors {clash} clash with the keys of {where} "
                         f"{reserved}; rename them")
    return task


def task_of(metadata: dict, where: str, error: type[Exception] = ValueError):
    """The task described in a session's or dataset's metadata (``"task"``), or the
    onion-sorting task for files written before the field; ``error`` names ``where`` when the
    field is not a task description."""
    from irl.domains.onion_sorting import SORTING_TASK
    from irl.domains.task import TaskDescription

    doc = metadata.get("task")
    if doc is None:
        return SORTING_TASK
    try:
        return TaskDescription.from_dict(doc)
    except (TypeError, ValueError) as exc:
        raise error(f"{where}'s task is not a task description ({exc})") from None


def json_schema_bytes(schema: dict) -> bytes:
    """A JSON schema as the bytes of an MCAP ``jsonschema`` schema record."""
    return json.dumps(schema, sort_keys=True).encode()
