"""What every Rerun logger of onionsort shares: opening a stream, classes, cameras, series.

A stream is opened once with its one blueprint (:func:`open_recording`) and closed with
:func:`close_recording`. It goes to one target or to several at once: an ``.rrd`` file, a
spawned viewer, or a viewer on another machine reached over gRPC
(``rerun+http://HOST:9876/proxy``). A command's ``--connect URL`` streams to the viewer *in
addition to* the ``.rrd`` file it writes (:func:`rerun_targets`): the file stays the complete
record, the viewer shows the run live. The URL is checked where the command's configuration
is built (:func:`check_viewer_url`) and the viewer is reached before the work starts
(:func:`reach_viewer`), so a wrong address fails at once, not after the run; a viewer lost on
the way only costs the live view (a warning), never the file.

Onion classes are drawn from one annotation context built from
:data:`recordings.session.schema.CLASS_NAMES` and :data:`recordings.session.schema.CLASS_COLORS`,
logged static at the root so that every box of every logger (``class_ids``) gets the same name and
colour. A camera is a static pinhole at ``<root>/camera`` with its images under it::

    <root>/camera          Pinhole (static): intrinsics and resolution
    <root>/camera/color    the colour image (JPEG or raw RGB)
    <root>/camera/depth    DepthImage (``meter`` units per metre); the loggers leave out (depth 0)
                           what lies farther than :data:`WORK_CELL_DEPTH_M` along the optical
                           axis: the floor and the far plane beyond the work cell

A blueprint shows a view only where the recording holds its data: a logger that cannot know
that when it opens notes what it logged and sends the blueprint built from it once, when it
closes (:func:`send_layout`); a live viewer shows Rerun's own layout until then.

Scalar series are sent whole with :func:`send_series` (one ``rr.send_columns`` call per
series), their names logged static once with :func:`log_series_names`.
"""

from __future__ import annotations

import logging
import socket
import urllib.parse
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from irl.domains.task import TaskDescription
from recordings.session.schema import CLASS_COLORS, CLASS_NAMES

__all__ = [
    "GRPC_SCHEMES",
    "WORK_CELL_DEPTH_M",
    "check_viewer_url",
    "class_annotations",
    "close_recording",
    "factor_values",
    "log_camera_images",
    "log_class_annotations",
    "log_pinhole",
    "log_series_names",
    "open_recording",
    "reach_viewer",
    "rerun_targets",
    "send_layout",
    "send_series",
    "value_labels",
]

logger = logging.getLogger(__name__)

#: ``.rrd`` files being written, by recording id: [(temporary name, final name)], and the
#: viewer URLs the stream goes to.
_PENDING: dict[str, tuple[list[tuple[Path, Path]], list[str]]] = {}
#: URL schemes of a viewer or server reached over gRPC (``rr.RecordingStream.connect_grpc``).
GRPC_SCHEMES = ("rerun+http://", "rerun+https://", "rerun://")

#: Depth (m, along a camera's optical axis) beyond which a depth image shows no work cell: the
#: main camera stands 1.5 m in front of the belt and sees the belt's ends, the bin, the sorter
#: and the Sawyer within 2.5 m; farther lie the floor and the far plane (5 m), which would hide
#: the work cell in 3D behind a wall of points.
WORK_CELL_DEPTH_M = 3.0

#: One target of a stream: an ``.rrd`` path, ``"spawn"`` or a gRPC URL.
Target = str | Path


def check_viewer_url(url: str) -> str:
    """``url`` if it is the gRPC URL of a Rerun viewer: ``rerun+http://HOST:PORT/proxy`` (also
    ``rerun+https://`` and ``rerun://``), with an explicit port.

    Raises
    ------
    ValueError
        Naming what is wrong and the URL given.
    """
    def bad(why: str) -> ValueError:
        return ValueError(f"connect must be the gRPC URL of a Rerun viewer, "
                          f"rerun+http://HOST:PORT/proxy ({why}); got {url!r}")

    if not isinstance(url, str) or not url.startswith(GRPC_SCHEMES):
        raise bad(f"the scheme must be {', '.join(s[:-3] for s in GRPC_SCHEMES)}")
    parts = urllib.parse.urlsplit(url)
    try:
        port = parts.port
    except ValueError:
        raise bad("the port is not a number from 0 to 65535") from None
    if not parts.hostname:
        raise bad("no host")
    if port is None or port == 0:
        raise bad("no port")
    if parts.path != "/proxy" or parts.query or parts.fragment:
        raise bad("the path must be /proxy")
    return url


def reach_viewer(url: str, timeout: float = 5.0) -> None:
    """Make sure something listens at the viewer URL ``url`` (a TCP connection to its host and
    port), so that a run does not discover a wrong address only when it ends.

    Raises
    ------
    ValueError
        If ``url`` is no viewer URL (:func:`check_viewer_url`).
    ConnectionError
        If nothing answers there within ``timeout`` seconds.
    """
    parts = urllib.parse.urlsplit(check_viewer_url(url))
    try:
        with socket.create_connection((parts.hostname, parts.port), timeout=timeout):
            pass
    except OSError as exc:
        raise ConnectionError(f"no Rerun viewer answers at {url} ({exc.strerror or exc}); "
                              "start one there (`rerun`) or give its address") from None


def rerun_targets(file: Path | None, connect: str | None) -> Target | tuple[Target, ...] | None:
    """The target of :func:`open_recording` for a stage that writes ``file`` (or None) and
    streams to the viewer at ``connect`` (or None): one, both, or None for no recording."""
    targets = tuple(t for t in (file, connect) if t is not None)
    return None if not targets else targets[0] if len(targets) == 1 else targets


def open_recording(application_id: str, target: Target | Sequence[Target],
                   blueprint: rrb.Blueprint | None = None) -> rr.RecordingStream:
    """A new recording stream sent to ``target`` with ``blueprint`` as its one layout.

    Parameters
    ----------
    application_id : str
        The application the recording belongs to (the viewer groups recordings by it).
    target : path-like, str, or a sequence of them
        An ``.rrd`` file to write (its folder is created), ``"spawn"`` to start (or reach) a
        local viewer, or a gRPC URL (``rerun+http://host:port/proxy``; also ``rerun+https://``
        and ``rerun://``) of a running viewer; or several files and URLs (not ``"spawn"``), all
        of which get the whole stream (:func:`rerun_targets`).
    blueprint : rerun.blueprint.Blueprint or None
        The layout, sent once as the recording's default blueprint (to every target).

    Returns
    -------
    rerun.RecordingStream
        Close it with :func:`close_recording`.

    Raises
    ------
    ValueError
        If ``application_id`` is empty, or a target is none of the above.
    """
    if not application_id:
        raise ValueError(f"application_id must be a non-empty string; got {application_id!r}")
    targets = list(target) if isinstance(target, list | tuple) else [target]
    if not targets:
        raise ValueError("target must name at least one .rrd file, 'spawn' or gRPC URL; got "
                         "none")
    files: list[tuple[Path, Path]] = []
    urls: list[str] = []
    spawn = False
    for each in targets:
        text = str(each)
        if isinstance(each, str) and text == "spawn":
            spawn = True
        elif isinstance(each, str) and text.startswith(GRPC_SCHEMES):
            urls.append(check_viewer_url(text))
        elif isinstance(each, str | Path) and Path(text).suffix == ".rrd":
            path = Path(text)
            # written under a temporary name, renamed by close_recording once complete: a
            # process killed on the way leaves ``NAME.rrd.partial``, never a truncated NAME.rrd
            files.append((path.with_name(path.name + ".partial"), path))
        else:
            raise ValueError(f"target must be an .rrd file, 'spawn' or a gRPC URL starting "
                             f"with {' or '.join(GRPC_SCHEMES)}; got {each!r}")
    if spawn and len(targets) > 1:
        raise ValueError(f"'spawn' cannot be combined with other targets; got {targets!r}")
    rec = rr.RecordingStream(application_id)
    if spawn:
        rec.spawn(default_blueprint=blueprint)
    else:
        for _, path in files:
            path.parent.mkdir(parents=True, exist_ok=True)
        try:
            sinks = [rr.FileSink(partial) for partial, _ in files] + [rr.GrpcSink(url)
                                                                      for url in urls]
            rec.set_sinks(*sinks, default_blueprint=blueprint)
        except RuntimeError as exc:  # an endpoint the SDK refuses
            raise ValueError(f"cannot open the Rerun targets {targets!r}: {exc}") from None
    _PENDING[rec.get_recording_id()] = (files, urls)
    logger.debug("rerun recording %s (%s) -> %s", application_id, rec.get_recording_id(),
                 ", ".join(map(str, targets)))
    return rec


def close_recording(rec: rr.RecordingStream) -> None:
    """Flush everything logged to ``rec`` to its files and viewers and disconnect it; a file
    gets its final name only now.

    A viewer that cannot be reached any more is a warning: the files are complete all the
    same. Any other failure to flush leaves the files under their temporary names.

    Raises
    ------
    OSError
        If the stream could not be flushed to its files.
    """
    files, urls = _PENDING.pop(rec.get_recording_id(), ([], []))
    try:
        rec.flush()
    except RuntimeError as exc:
        # the SDK names the viewer's URL, or only its gRPC sink ("gRPC connection is open,
        # but flush still failed"); a file sink's failure names neither
        lost = [url for url in urls if url in str(exc)] or (urls if "grpc" in str(exc).lower()
                                                            else [])
        rec.disconnect()
        if not lost:
            raise OSError(f"the Rerun recording {', '.join(str(p) for _, p in files)} could "
                          f"not be written: {exc}") from None
        logger.warning("the Rerun viewer at %s did not take the whole recording (%s); the "
                       "files are complete", ", ".join(lost), exc)
    else:
        rec.disconnect()
    for partial, path in files:
        partial.replace(path)


def send_layout(rec: rr.RecordingStream, blueprint: rrb.Blueprint) -> None:
    """Send ``blueprint`` as the recording's one layout (active and default).

    A logger whose views depend on what it logged sends it once, when it closes: a recording
    holding two blueprints opens on either (Rerun's web viewer takes the first it reads), so a
    layout sent early and corrected later may still show empty views.
    """
    rec.send_blueprint(blueprint, make_active=True, make_default=True)


def class_annotations() -> rr.AnnotationContext:
    """The onion classes (id, name, colour) of :mod:`recordings.session.schema` as an annotation
    context."""
    return rr.AnnotationContext([(cid, name, CLASS_COLORS[cid])
                                 for cid, name in sorted(CLASS_NAMES.items())])


def log_class_annotations(rec: rr.RecordingStream, entity: str = "/") -> None:
    """Log the class annotation context static at ``entity`` (the root: every entity)."""
    rec.log(entity, class_annotations(), static=True)


def log_pinhole(rec: rr.RecordingStream, root: str, K: Sequence[Sequence[float]] | np.ndarray,
                width: int, height: int) -> None:
    """Log ``<root>/camera`` as a static pinhole camera of intrinsics ``K`` (3, 3).

    Raises
    ------
    ValueError
        If ``K`` is not 3 x 3 or the resolution is not positive.
    """
    K = np.asarray(K, float)
    if K.shape != (3, 3):
        raise ValueError(f"K must be a 3 x 3 intrinsics matrix; got shape {K.shape}")
    if int(width) < 1 or int(height) < 1:
        raise ValueError(f"width and height must be positive; got {width} x {height}")
    rec.log(f"{root}/camera", rr.Pinhole(image_from_camera=K, resolution=[int(width),
                                                                            int(height)]),
            static=True)


def log_camera_images(rec: rr.RecordingStream, root: str, *, color: np.ndarray | None = None,
                      color_jpeg: bytes | None = None, depth: np.ndarray | None = None,
                      depth_meter: float = 1.0, jpeg_quality: int | None = None,
                      max_depth: float | None = None) -> None:
    """Log a camera's images at the current time: ``<root>/camera/color`` and
    ``<root>/camera/depth``.

    Parameters
    ----------
    rec : rerun.RecordingStream
    root : str
        The logger's entity root.
    color : ndarray of shape (H, W, 3) or None
        uint8 RGB (compressed to JPEG if ``jpeg_quality`` is given).
    color_jpeg : bytes or None
        An already encoded JPEG (instead of ``color``).
    depth : ndarray of shape (H, W) or None
        Depth, ``depth_meter`` units per metre (1.0 for float metres, 1000 for uint16 mm).
    depth_meter : float
    jpeg_quality : int or None
    max_depth : float or None
        Depth in metres beyond which a pixel is logged as 0 (no measurement: Rerun draws no
        point for it), and non-finite depths too; None keeps every pixel.

    Raises
    ------
    ValueError
        If both ``color`` and ``color_jpeg`` are given.
    """
    if color is not None and color_jpeg is not None:
        raise ValueError("give color or color_jpeg, not both")
    if color_jpeg is not None:
        rec.log(f"{root}/camera/color", rr.EncodedImage(contents=color_jpeg,
                                                        media_type="image/jpeg"))
    elif color is not None:
        image = rr.Image(np.asarray(color))
        rec.log(f"{root}/camera/color",
                image if jpeg_quality is None else image.compress(jpeg_quality=jpeg_quality))
    if depth is not None:
        depth = np.asarray(depth)
        if max_depth is not None:
            far = ~np.isfinite(depth) | (depth > max_depth * depth_meter)
            if far.any():
                depth = np.where(far, 0, depth).astype(depth.dtype)
        rec.log(f"{root}/camera/depth", rr.DepthImage(depth, meter=depth_meter))


def value_labels(names: Sequence[str]) -> str:
    """``"0=name, 1=name, ..."``: the value labels of a series of indices into ``names``."""
    return ", ".join(f"{i}={name}" for i, name in enumerate(names))


def factor_values(task: TaskDescription) -> dict[str, tuple[str, ...]]:
    """The series of a step of ``task``: each state factor's value names, in the order of the
    state encoding, then ``"action"`` with the action names."""
    if "action" in task.factors:
        raise ValueError(f"task {task.name!r} has a state factor named 'action', which would "
                         "hide the action series; rename it")
    return {**task.factors, "action": task.action_names}


def log_series_names(rec: rr.RecordingStream, names: Mapping[str, str | Sequence[str]],
                     colors: Mapping[str, Sequence[int]] | None = None) -> None:
    """Log static ``SeriesLines`` names (and colours) of series, ``{entity: name(s)}``."""
    colors = colors or {}
    for entity, name in names.items():
        rec.log(entity, rr.SeriesLines(names=name, colors=colors.get(entity)), static=True)


def send_series(rec: rr.RecordingStream, entity: str, indexes: Iterable[rr.TimeColumn],
                values: Sequence[float] | np.ndarray) -> None:
    """Send a whole scalar series in one ``send_columns`` call.

    Parameters
    ----------
    rec : rerun.RecordingStream
    entity : str
    indexes : iterable of rerun.TimeColumn
        The time of each row, on one or more timelines.
    values : array-like of shape (n,) or (n, k)
        One scalar per row, or ``k`` scalars per row (``k`` lines).
    """
    values = np.asarray(values, float)
    if values.ndim not in (1, 2):
        raise ValueError(f"values must have shape (n,) or (n, k); got {values.shape}")
    if len(values) == 0:
        return
    columns = rr.Scalars.columns(scalars=values)
    if values.ndim == 2:
        columns = columns.partition([values.shape[1]] * len(values))
    rec.send_columns(entity, indexes=list(indexes), columns=columns)
