"""Frame sources for importing sessions: a video file or a camera, read through OpenCV.

Both sources are iterables of :class:`SourceFrame` (RGB uint8 images with a frame index and a
time in nanoseconds since the first frame) and context managers that release the capture. Both
are opened, and their first frame read, when they are made, so a missing file, a file OpenCV
cannot decode, a video without frames or an index with no camera fails at once with a one-line
:class:`SourceError` naming the source and saying what to do. A source is read once: iterating
it a second time raises.

Timestamps: a video file's frame times come from OpenCV's ``CAP_PROP_POS_MSEC`` while that is
sane (finite and increasing), else from ``index / fps``; a camera's from the wall clock
(``time.monotonic_ns``) since its first frame.

:func:`default_intrinsics` gives the pinhole matrix assumed for a camera whose calibration is not
known (no ``--intrinsics``); :func:`load_intrinsics` reads a calibration from a JSON file.

Layouts: ``color[v, u, c]`` (H, W, 3) uint8 RGB; ``K`` (3, 3) pixels.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "DEFAULT_FPS",
    "CameraNotFoundError",
    "CameraSource",
    "EmptyVideoError",
    "IntrinsicsError",
    "SourceError",
    "SourceFrame",
    "SourceNotFoundError",
    "VideoFileSource",
    "default_intrinsics",
    "load_intrinsics",
    "write_video",
]

logger = logging.getLogger(__name__)

#: Frame rate assumed for a video that reports none (and whose frame times are not sane).
DEFAULT_FPS = 30.0
_MAX_FPS = 1000.0


class SourceError(ValueError):
    """A frame source cannot be opened or read; the message names it and says what to do."""


class SourceNotFoundError(SourceError, FileNotFoundError):
    """The video file does not exist."""


class EmptyVideoError(SourceError):
    """The video opens but holds no frame."""


class CameraNotFoundError(SourceError):
    """No camera answers at the index, or it gives no frame."""


class IntrinsicsError(ValueError):
    """An intrinsics file is not a valid pinhole calibration."""


@dataclass(frozen=True)
class SourceFrame:
    """One frame of a source.

    Attributes
    ----------
    index : int
        Position in the source, from 0.
    time_ns : int
        Time since the source's first frame, nanoseconds (>= 0).
    color : ndarray of shape (H, W, 3)
        uint8 RGB.
    """

    index: int
    time_ns: int
    color: np.ndarray = field(repr=False)

    def __post_init__(self) -> None:
        if int(self.index) < 0:
            raise ValueError(f"index must be >= 0; got {self.index}")
        if int(self.time_ns) < 0:
            raise ValueError(f"time_ns must be >= 0; got {self.time_ns}")
        c = self.color
        if not isinstance(c, np.ndarray) or c.dtype != np.uint8 or c.ndim != 3 or c.shape[2] != 3:
            raise ValueError("color must be an (H, W, 3) uint8 array; got "
                             f"{getattr(c, 'shape', type(c).__name__)} "
                             f"{getattr(c, 'dtype', '')}".rstrip())


@contextlib.contextmanager
def _quiet_native_stderr():
    """Silence what OpenCV's and FFmpeg's native code print while a capture opens (they write
    to file descriptor 2 directly); our own error then says what is wrong in one line."""
    import os
    import sys

    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):  # no usable descriptor 2 (e.g. some embedded hosts)
        yield
        return
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def _to_rgb(image: np.ndarray) -> np.ndarray:
    """An OpenCV frame (BGR, BGRA or grey) as (H, W, 3) uint8 RGB."""
    if image.ndim == 2:
        image = np.repeat(image[..., None], 3, axis=2)
    elif image.shape[2] == 4:
        image = image[..., :3]
    if image.dtype != np.uint8:
        image = np.clip(image, 0, 255).astype(np.uint8)
    return np.ascontiguousarray(image[..., 2::-1])


def _sane_fps(value: float) -> float | None:
    return float(value) if math.isfinite(value) and 0.0 < value <= _MAX_FPS else None


class _CaptureSource:
    """What the two sources share: the capture, its properties, release and one-shot reading."""

    name: str

    def __init__(self) -> None:
        self._cap: Any = None
        self._first: np.ndarray | None = None
        self._iterated = False
        self._width = self._height = 0
        self._fps: float | None = None

    def _adopt(self, cap: Any, first: np.ndarray) -> None:
        import cv2

        self._cap, self._first = cap, _to_rgb(first)
        self._height, self._width = self._first.shape[:2]
        self._fps = _sane_fps(cap.get(cv2.CAP_PROP_FPS))

    @property
    def fps(self) -> float | None:
        """Frame rate the capture reports, frames per second; None if it reports none."""
        return self._fps

    @property
    def width(self) -> int:
        """Image width, pixels (of the first frame)."""
        return self._width

    @property
    def height(self) -> int:
        """Image height, pixels (of the first frame)."""
        return self._height

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close()

    def close(self) -> None:
        """Release the capture; idempotent."""
        if self._cap is not None:
            self._cap.release()
            self._cap = None

    def __del__(self) -> None:
        with contextlib.suppress(Exception):  # best effort, e.g. at interpreter shutdown
            self.close()

    def __iter__(self) -> Iterator[SourceFrame]:
        if self._iterated:
            raise RuntimeError(f"{self.name} has been read already; a source is read once "
                               "(open it again)")
        if self._cap is None:
            raise RuntimeError(f"{self.name} is closed")
        self._iterated = True
        return self._frames()

    def _frames(self) -> Iterator[SourceFrame]:  # pragma: no cover - overridden
        raise NotImplementedError

    def __repr__(self) -> str:
        return (f"{type(self).__name__}({self.name!r}, {self.width}x{self.height}, "
                f"fps={self.fps})")


class VideoFileSource(_CaptureSource):
    """The frames of a video file, read with ``cv2.VideoCapture``.

    Parameters
    ----------
    path : path-like
        Any container and codec this OpenCV build decodes (MP4/mp4v, AVI/MJPG, ...).

    Raises
    ------
    SourceNotFoundError
        If the file does not exist.
    SourceError
        If it is a directory, or OpenCV cannot open or decode it.
    EmptyVideoError
        If it opens but holds no frame.
    """

    def __init__(self, path: str | Path) -> None:
        import cv2

        super().__init__()
        self.path = Path(path)
        self.name = str(self.path)
        if not self.path.exists():
            raise SourceNotFoundError(f"{self.path}: no such video file; check the path")
        if not self.path.is_file():
            raise SourceError(f"{self.path} is not a file; give the path of a video file")
        with _quiet_native_stderr():
            cap = cv2.VideoCapture(str(self.path))
        if not cap.isOpened():
            cap.release()
            raise SourceError(
                f"OpenCV cannot open {self.path} as a video (not a video, truncated, holding no "
                "frames, or in a codec this build lacks); re-encode it, e.g. `ffmpeg -i IN "
                "-c:v mpeg4 -q:v 2 OUT.mp4`")
        ok, first = cap.read()
        if not ok or first is None:
            cap.release()
            raise EmptyVideoError(f"{self.path} holds no frame OpenCV can decode; record or "
                                  "re-encode the video")
        self._adopt(cap, first)
        count = cap.get(cv2.CAP_PROP_FRAME_COUNT)
        #: Frames the container announces (an estimate; None if unknown).
        self.frame_count: int | None = int(count) if math.isfinite(count) and count > 0 else None

    def _frames(self) -> Iterator[SourceFrame]:
        import cv2

        cap, fps = self._cap, self._fps
        if fps is None:
            logger.warning("%s reports no frame rate; assuming %.0f fps where frame times are "
                           "missing", self.name, DEFAULT_FPS)
            fps = DEFAULT_FPS
        image, index = self._first, 0
        self._first = None
        use_msec, msec0, last_msec = True, 0.0, -math.inf
        while True:
            msec = cap.get(cv2.CAP_PROP_POS_MSEC)
            if use_msec and not (math.isfinite(msec) and msec >= 0.0
                                 and (index == 0 or msec > last_msec)):
                use_msec = False
                logger.info("%s: frame times from index / fps (%.3g) from frame %d on; OpenCV "
                            "gave %r ms", self.name, fps, index, msec)
            if use_msec:
                if index == 0:
                    msec0 = msec
                last_msec = msec
                t = round((msec - msec0) * 1e6)
            else:
                t = round(index / fps * 1e9)
            yield SourceFrame(index, t, image if index == 0 else _to_rgb(image))
            if self._cap is None:  # closed while being read
                return
            ok, image = cap.read()
            if not ok or image is None:
                break
            index += 1
        if self.frame_count is not None and index + 1 < 0.9 * self.frame_count:
            logger.warning("%s: read %d frames of the %d the file announces; it may be "
                           "truncated or partly undecodable", self.name, index + 1,
                           self.frame_count)


class CameraSource(_CaptureSource):
    """Live frames of a camera, read with ``cv2.VideoCapture(index)``.

    Reading stops after ``max_frames`` frames, once ``max_seconds`` have passed since the first
    frame, when the camera stops giving frames, or when the consumer stops iterating (e.g. on
    Ctrl-C); with neither limit it runs until one of the latter.

    Parameters
    ----------
    index : int
        The camera's OpenCV index (``/dev/video<index>`` on Linux).
    max_frames : int or None
        At most this many frames (>= 1).
    max_seconds : float or None
        Stop at the first frame later than this many seconds after the first (> 0).

    Raises
    ------
    CameraNotFoundError
        If no camera opens at ``index``, or it gives no first frame.
    """

    def __init__(self, index: int, *, max_frames: int | None = None,
                 max_seconds: float | None = None) -> None:
        import cv2

        super().__init__()
        if isinstance(index, bool) or not isinstance(index, (int, np.integer)) or index < 0:
            raise ValueError(f"index must be an int >= 0; got {index!r}")
        if max_frames is not None and int(max_frames) < 1:
            raise ValueError(f"max_frames must be >= 1 or None; got {max_frames}")
        if max_seconds is not None and not (math.isfinite(max_seconds) and max_seconds > 0):
            raise ValueError(f"max_seconds must be > 0 or None; got {max_seconds}")
        self.index = int(index)
        self.name = f"camera {self.index}"
        self.max_frames = None if max_frames is None else int(max_frames)
        self.max_seconds = None if max_seconds is None else float(max_seconds)
        with _quiet_native_stderr():
            cap = cv2.VideoCapture(self.index)
        if not cap.isOpened():
            cap.release()
            raise CameraNotFoundError(
                f"no camera at index {self.index} (OpenCV could not open it); check that it "
                "is connected and not in use, and try another index (`v4l2-ctl "
                "--list-devices` lists them on Linux)")
        ok, first = cap.read()
        if not ok or first is None:
            cap.release()
            raise CameraNotFoundError(
                f"camera {self.index} opened but gave no frame; check that no other program "
                "holds it, or try another index")
        self._t0 = time.monotonic_ns()
        self._adopt(cap, first)

    def _frames(self) -> Iterator[SourceFrame]:
        cap, image, index, t = self._cap, self._first, 0, 0
        self._first = None
        limit_ns = None if self.max_seconds is None else round(self.max_seconds * 1e9)
        while True:
            yield SourceFrame(index, t, image if index == 0 else _to_rgb(image))
            index += 1
            if self._cap is None or (self.max_frames is not None and index >= self.max_frames):
                return
            ok, image = cap.read()
            if not ok or image is None:
                logger.warning("%s stopped giving frames after %d", self.name, index)
                return
            t = time.monotonic_ns() - self._t0
            if limit_ns is not None and t > limit_ns:
                return


def default_intrinsics(width: int, height: int, hfov_deg: float = 60.0) -> np.ndarray:
    """The pinhole matrix assumed for a camera of unknown calibration (no ``--intrinsics``).

    Square pixels, the principal point at the image centre, and a horizontal field of view of
    ``hfov_deg`` (60 degrees: a typical webcam). Good enough to display a session; measure
    the real one (e.g. ``cv2.calibrateCamera``) and pass it as ``--intrinsics`` when metric
    geometry matters.

    Parameters
    ----------
    width, height : int
        Image size, pixels (> 0).
    hfov_deg : float
        Horizontal field of view, degrees, in (0, 180).

    Returns
    -------
    K : ndarray of shape (3, 3)
        ``[[f, 0, width / 2], [0, f, height / 2], [0, 0, 1]]`` with
        ``f = width / 2 / tan(hfov / 2)``.
    """
    if int(width) <= 0 or int(height) <= 0:
        raise ValueError(f"width and height must be > 0; got {width}x{height}")
    if not (math.isfinite(hfov_deg) and 0.0 < hfov_deg < 180.0):
        raise ValueError(f"hfov_deg must be in (0, 180); got {hfov_deg}")
    f = 0.5 * width / math.tan(math.radians(hfov_deg) / 2.0)
    return np.array([[f, 0.0, width / 2.0], [0.0, f, height / 2.0], [0.0, 0.0, 1.0]])


_FIELDS = ("fx", "fy", "cx", "cy")
_FORMATS = ('{"K": [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]} or '
            '{"fx": .., "fy": .., "cx": .., "cy": ..}')


def load_intrinsics(path: str | Path) -> np.ndarray:
    """Read a camera's pinhole matrix from a JSON file.

    The file holds either ``{"K": [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]}`` or
    ``{"fx": .., "fy": .., "cx": .., "cy": ..}`` (other keys are ignored).

    Parameters
    ----------
    path : path-like

    Returns
    -------
    K : ndarray of shape (3, 3)
        float64, ``fx, fy > 0``, last row ``[0, 0, 1]``.

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    IntrinsicsError
        If it is not JSON, or holds neither form, or values that are not a pinhole matrix.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such intrinsics file; check the path")
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise IntrinsicsError(f"{path} is not JSON ({exc}); write it as {_FORMATS}") from None
    if not isinstance(data, dict):
        raise IntrinsicsError(f"{path} holds a JSON {type(data).__name__}; write it as "
                              f"{_FORMATS}")
    has_k, has_f = "K" in data, any(k in data for k in _FIELDS)
    if has_k == has_f:
        raise IntrinsicsError(f"{path} must hold either 'K' or 'fx', 'fy', 'cx', 'cy'"
                              f"{' (not both)' if has_k else ''}; write it as {_FORMATS}")
    try:
        if has_k:
            K = np.array(data["K"], dtype=float)
        else:
            missing = [k for k in _FIELDS if k not in data]
            if missing:
                raise IntrinsicsError(f"{path} lacks {', '.join(missing)}; write it as "
                                      f"{_FORMATS}")
            fx, fy, cx, cy = (float(data[k]) for k in _FIELDS)
            K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    except (TypeError, ValueError) as exc:
        if isinstance(exc, IntrinsicsError):
            raise
        raise IntrinsicsError(f"{path}: the intrinsics must be numbers ({exc}); write them as "
                              f"{_FORMATS}") from None
    if K.shape != (3, 3):
        raise IntrinsicsError(f"{path}: K must be 3x3; got shape {K.shape}")
    if not np.all(np.isfinite(K)):
        raise IntrinsicsError(f"{path}: K must be finite; got {K.tolist()}")
    if not np.allclose(K[2], [0.0, 0.0, 1.0]):
        raise IntrinsicsError(f"{path}: K's last row must be [0, 0, 1]; got {K[2].tolist()}")
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise IntrinsicsError(f"{path}: fx and fy must be > 0; got {K[0, 0]}, {K[1, 1]}")
    return K


def write_video(path: str | Path, frames, fps: float, fourcc: str = "mp4v") -> Path:
    """Write RGB frames (each (H, W, 3) uint8, all one size) as a video file.

    The inverse of :class:`VideoFileSource`: how a simulated session becomes the plain video a
    real camera would give (MP4 with the ``mp4v`` codec by default; this OpenCV build has no
    H.264 encoder). Written to a temporary name and renamed.

    Raises
    ------
    ValueError
        If there are no frames, ``fps`` is not positive, or OpenCV cannot write the codec.
    """
    import cv2

    path = Path(path)
    if not fps > 0:
        raise ValueError(f"fps must be > 0; got {fps}")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.stem + ".partial" + path.suffix)  # OpenCV picks the container
    writer = None                                               # by the suffix
    n = 0
    try:
        for rgb in frames:
            rgb = np.asarray(rgb, np.uint8)
            if writer is None:
                h, w = rgb.shape[:2]
                writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*fourcc), fps, (w, h))
                if not writer.isOpened():
                    raise ValueError(f"OpenCV cannot write {fourcc!r} video to {path}")
            writer.write(np.ascontiguousarray(rgb[..., ::-1]))
            n += 1
        if writer is None:
            raise ValueError(f"no frames to write to {path}")
        writer.release()
        writer = None
        tmp.replace(path)
    finally:
        if writer is not None:
            writer.release()
        tmp.unlink(missing_ok=True)
    logger.info("wrote %d frames to %s", n, path)
    return path
