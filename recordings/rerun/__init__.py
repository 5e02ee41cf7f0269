"""The common Rerun logging of onionsort: sessions, their perception, the work cell in 3D.

=============  ====================================  ==========================================
root           logger                                what
=============  ====================================  ==========================================
``record/``    :class:`SessionLogger`                recorded sessions: cameras, ground truth
``perceive/``  :class:`PerceptionLogger`             what perception made of a session
=============  ====================================  ==========================================

The logging of one stage lives beside that stage and builds on these pieces: ``learn/``
(:mod:`onionsort.stages.learn_rerun`: a learner's objective, reward and policy) and
``evaluate/`` (:mod:`onionsort.stages.evaluate_rerun`: the Sawyer executing a policy).

Shared pieces (:mod:`recordings.rerun.common`): :func:`open_recording` opens a stream to an
``.rrd`` file, a spawned viewer or a gRPC URL with one blueprint; the onion classes' annotation
context comes from :mod:`recordings.session.schema`; a camera is a static pinhole ``<root>/camera``
with ``color`` and ``depth`` under it. The work cell in 3D (:mod:`recordings.rerun.world`): each
blueprint has one ``Spatial3DView`` at its root, showing the pinhole cameras' frustums with their
images, the bodies of the work cell and the Sawyer from its URDF, animated from its joint
angles, and nothing else (no 2D entity outside a pinhole, no series, no text). Each blueprint
has a view only for what its recording holds (the loggers that learn it as they log send it
when they close: :func:`~recordings.rerun.common.send_layout`). Importing this package loads
the Rerun SDK.
"""

from __future__ import annotations

from recordings.rerun.common import (
    class_annotations,
    close_recording,
    log_camera_images,
    log_class_annotations,
    log_pinhole,
    open_recording,
    send_series,
)
from recordings.rerun.perceive import PerceptionLogger, read_detections
from recordings.rerun.session import SessionLogger, session_blueprint
from recordings.rerun.world import WorldLogger, world_view

__all__ = [
    "PerceptionLogger",
    "SessionLogger",
    "WorldLogger",
    "class_annotations",
    "close_recording",
    "log_camera_images",
    "log_class_annotations",
    "log_pinhole",
    "open_recording",
    "read_detections",
    "send_series",
    "session_blueprint",
    "world_view",
]
