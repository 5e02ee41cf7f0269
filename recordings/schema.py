"""The session format: topics, message schemas and the session metadata record.

One MCAP file per session. Images use Foxglove's well-known protobuf schemas; ground truth uses
JSON messages with JSON-schema channels, each on its own topic. Every message's ``log_time`` is
the simulated time in nanoseconds and its ``sequence`` the frame index.

=========================  ==========================  ==========================================
topic                      schema                      content
=========================  ==========================  ==========================================
/camera/color              foxglove.CompressedImage    main RGB camera, JPEG, every frame
/camera/depth              foxglove.RawImage           depth, 16UC1 millimetres, every frame
/camera/calibration        foxglove.CameraCalibration  pinhole K, P of the main camera
/inspection/color          foxglove.CompressedImage    inspection view, PNG, first frame of a step
/inspection/calibration    foxglove.CameraCalibration  pinhole K, P of the inspection view
/ground_truth/state        onionsort.GroundTruthState  true MDP state of each frame
/ground_truth/action       onionsort.GroundTruthStep   (s_t, a_t, s_t+1, occluded), once a step
/ground_truth/boxes        onionsort.GroundTruthBoxes  boxes of visible onions (segmentation)
/ground_truth/annotations  foxglove.ImageAnnotations   the same boxes, drawable over /camera/color
/ground_truth/onions       onionsort.GroundTruthOnions  every onion's class and position
=========================  ==========================  ==========================================

Metadata records: ``onionsort.session`` (written first: format, seed, configuration, software
version) and ``onionsort.session.end`` (written last: status, frame and step counts).
"""

from __future__ import annotations

import json

__all__ = [
    "CLASS_NAMES",
    "END_METADATA",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "JSON_SCHEMAS",
    "SESSION_METADATA",
    "Topic",
    "json_schema_bytes",
]

FORMAT_NAME = "onionsort-session"
FORMAT_VERSION = "1"
SESSION_METADATA = "onionsort.session"
END_METADATA = "onionsort.session.end"

#: Class ids of onions in box annotations.
CLASS_NAMES = {0: "good", 1: "blemished"}


class Topic:
    """Topic names of a session."""

    COLOR = "/camera/color"
    DEPTH = "/camera/depth"
    CALIBRATION = "/camera/calibration"
    INSPECTION = "/inspection/color"
    INSPECTION_CALIBRATION = "/inspection/calibration"
    STATE = "/ground_truth/state"
    ACTION = "/ground_truth/action"
    BOXES = "/ground_truth/boxes"
    ANNOTATIONS = "/ground_truth/annotations"
    ONIONS = "/ground_truth/onions"


_INT = {"type": "integer"}
_NUM = {"type": "number"}
_STR = {"type": "string"}
_BOOL = {"type": "boolean"}

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


def json_schema_bytes(schema: dict) -> bytes:
    """A JSON schema as the bytes of an MCAP ``jsonschema`` schema record."""
    return json.dumps(schema, sort_keys=True).encode()
