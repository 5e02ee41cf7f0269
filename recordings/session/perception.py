"""Perception topics of a session: detections, state estimates and occlusion calls.

``onionsort perceive`` adds these topics to a recorded session (:func:`add_perception`); the
reader then turns the session into the demonstration the learners use
(:meth:`recordings.Session.perceived_demonstration`), without any ground truth.

=========================  ==========================  ==========================================
topic                      schema                      content
=========================  ==========================  ==========================================
/perception/state          onionsort.PerceivedStep     per step: estimates with probabilities,
                                                       occluded call, pair observation (or null)
/perception/detections     onionsort.Detections        detector boxes on the main camera, per frame
/perception/annotations    foxglove.ImageAnnotations   the same boxes, drawable over /camera/color
/perception/inspection     onionsort.Detections        detector boxes on the inspection view
=========================  ==========================  ==========================================

A metadata record ``onionsort.perception`` says which models produced them (the names are
:class:`~recordings.session.schema.PerceptionTopic` and
:data:`~recordings.session.schema.PERCEPTION_METADATA`). The file is
rewritten into a temporary file beside it and renamed over it, so an interrupted run leaves the
original session intact.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping, Sequence
from pathlib import Path

from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations
from mcap.writer import Writer
from mcap_protobuf.schema import build_file_descriptor_set

from recordings.session.rewrite import rewrite_session
from recordings.session.schema import PERCEPTION_METADATA, PerceptionTopic, json_schema_bytes
from recordings.session.writer import box_annotations

__all__ = ["add_perception"]

logger = logging.getLogger(__name__)

_INT, _NUM, _BOOL = {"type": "integer"}, {"type": "number"}, {"type": "boolean"}
_DETECTIONS = {
    "type": "object",
    "description": "Detector output: boxes (pixels), class ids (0 good, 1 blemished), scores.",
    "properties": {
        "frame": _INT,
        "detections": {"type": "array", "items": {"type": "object", "properties": {
            "x_min": _NUM, "y_min": _NUM, "x_max": _NUM, "y_max": _NUM, "class_id": _INT,
            "score": _NUM}}},
    },
    "required": ["frame", "detections"],
}
_JSON_SCHEMAS = {
    PerceptionTopic.STATE: ("onionsort.PerceivedStep", {
        "type": "object",
        "description": "Perceived step: estimates of the state factors and the action with "
                       "class probabilities, the occluded call, the pair observation "
                       "s * A + a (null where occluded), the call on the onion seen in the "
                       "step's inspection views (inspected) and the fused probability behind "
                       "the prediction factor (p_blemished; null while no view showed it).",
        "properties": {
            "step": _INT, "frame": _INT, "occluded": _BOOL, "p_occluded": _NUM, "onion": _INT,
            "end_effector": _INT, "action": _INT, "prediction": _INT, "state": _INT,
            "observation": {"type": ["integer", "null"]},
            "inspected": {"type": ["integer", "null"]},
            "p_blemished": {"type": ["number", "null"]},
            "probs": {"type": "object"},
        },
        "required": ["step", "occluded", "observation"],
    }),
    PerceptionTopic.DETECTIONS: ("onionsort.Detections", _DETECTIONS),
    PerceptionTopic.INSPECTION: ("onionsort.Detections", _DETECTIONS),
}

#: A detection as stored: (x_min, y_min, x_max, y_max, class_id, score).
Detection = tuple[float, float, float, float, int, float]


def _detections_doc(frame: int, dets: Sequence[Detection]) -> bytes:
    return json.dumps({"frame": frame, "detections": [
        {"x_min": round(float(x0), 2), "y_min": round(float(y0), 2),
         "x_max": round(float(x1), 2), "y_max": round(float(y1), 2), "class_id": int(c),
         "score": round(float(s), 4)}
        for x0, y0, x1, y1, c, s in dets]}, separators=(",", ":")).encode()


def add_perception(path: str | Path, steps: Sequence[dict], *,
                   detections: Mapping[int, Sequence[Detection]],
                   inspection: Mapping[int, Sequence[Detection]],
                   frame_times: Mapping[int, int], models: dict, replace: bool = False) -> Path:
    """Rewrite a session file with perception topics added.

    Parameters
    ----------
    path : path-like
        A complete session written by ``onionsort record``.
    steps : sequence of dict
        One ``/perception/state`` message per step (see
        :meth:`state_abstraction.perceive.PerceivedStep.to_dict`), each with the index of the
        step's first ``frame``.
    detections, inspection : mapping of frame index -> sequence of Detection
        Detector output on the main camera and on the inspection view.
    frame_times : mapping of frame index -> int
        Log time (ns) of each frame.
    models : dict
        Which models produced the output (stored in the ``onionsort.perception`` record).
    replace : bool
        Replace perception topics already in the file instead of refusing.

    Raises
    ------
    FileExistsError
        If the session already holds perception topics and ``replace`` is False.
    """
    from mcap.reader import make_reader

    path = Path(path)
    with path.open("rb") as fh:
        names = [m.name for m in make_reader(fh, validate_crcs=True).iter_metadata()]
    if PERCEPTION_METADATA in names and not replace:
        raise FileExistsError(f"{path} already holds perception topics; pass --replace to "
                              "perceive it again")

    def add(writer: Writer) -> dict:
        _write_perception(writer, steps, detections, inspection, frame_times)
        return {PERCEPTION_METADATA: {k: v if isinstance(v, str) else json.dumps(v, sort_keys=True)
                                      for k, v in models.items()}}

    return rewrite_session(path, drop_topics=PerceptionTopic.ALL,
                           drop_metadata=(PERCEPTION_METADATA,), add=add)


def _write_perception(writer: Writer, steps, detections, inspection, frame_times) -> None:
    ids = {}
    for topic, (name, schema) in _JSON_SCHEMAS.items():
        sid = writer.register_schema(name, "jsonschema", json_schema_bytes(schema))
        ids[topic] = writer.register_channel(topic, "json", sid)
    sid = writer.register_schema(ImageAnnotations.DESCRIPTOR.full_name, "protobuf",
                                 build_file_descriptor_set(ImageAnnotations).SerializeToString())
    ids[PerceptionTopic.ANNOTATIONS] = writer.register_channel(
        PerceptionTopic.ANNOTATIONS, "protobuf", sid)

    def put(topic: str, data: bytes, frame: int, sequence: int) -> None:
        t = int(frame_times[frame])
        writer.add_message(ids[topic], log_time=t, data=data, publish_time=t, sequence=sequence)

    for frame, dets in sorted(detections.items()):
        put(PerceptionTopic.DETECTIONS, _detections_doc(frame, dets), frame, frame)
        boxes = [(x0, y0, x1, y1, int(c)) for x0, y0, x1, y1, c, _ in dets]
        put(PerceptionTopic.ANNOTATIONS,
            box_annotations(boxes, int(frame_times[frame])).SerializeToString(), frame, frame)
    for frame, dets in sorted(inspection.items()):
        put(PerceptionTopic.INSPECTION, _detections_doc(frame, dets), frame, frame)
    for doc in steps:
        put(PerceptionTopic.STATE, json.dumps(doc, separators=(",", ":")).encode(),
            int(doc["frame"]), int(doc["step"]))
