"""What every stage shares: logging its resolved configuration once, and atomic outputs.

A stage is a frozen config dataclass plus a function that runs it (``record(RecordConfig(...))``);
the CLI's commands only parse arguments into a config and call the stage. The same stages are
the Python API for scripting a study::

    from onionsort.stages import RecordConfig, record
    paths = record(RecordConfig(out=Path("runs/rec"), sessions=2))
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import logging
from collections.abc import Iterator
from pathlib import Path

from onionsort.perception_models import resolve_device

__all__ = ["check_output_folder", "log_config", "output_folder", "refuse_existing",
           "resolve_device", "write_json", "write_text"]

logger = logging.getLogger(__name__)


def _jsonable(value):
    if isinstance(value, Path):
        return str(value)
    if dataclasses.is_dataclass(value):
        return {f.name: _jsonable(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, tuple | list):
        return [_jsonable(v) for v in value]
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    return value


def log_config(stage: str, config) -> dict:
    """Log a stage's resolved configuration once, as JSON; return it as a dict."""
    resolved = _jsonable(config)
    logger.info("%s: %s", stage, json.dumps(resolved, sort_keys=True))
    return resolved


def write_json(path: Path, doc) -> Path:
    """Write ``doc`` as JSON to ``path`` through a temporary name, then rename it."""
    return write_text(path, json.dumps(doc, indent=1))


def write_text(path: Path, text: str) -> Path:
    """Write ``text`` to ``path`` (UTF-8) through a temporary name, then rename it."""
    path = Path(path)
    tmp = path.with_name(path.name + ".partial")
    try:
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def check_output_folder(folder: Path, what: str = "--out") -> Path:
    """Create ``folder`` (and parents) now and make sure a file can be written in it, before
    any expensive work, or fail clearly (``ValueError`` naming ``what`` and the folder)."""
    import tempfile

    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise ValueError(f"{what} {folder} is a file, not a folder; choose another") from None
    except OSError as exc:
        raise ValueError(f"{what} {folder} cannot be created ({exc.strerror or exc}); "
                         "choose another") from None
    try:  # a folder that exists may still refuse files (permissions, a read-only disk)
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".onionsort-probe-",
                                         suffix=".partial"):
            pass
    except OSError as exc:
        raise ValueError(f"{what} {folder} cannot be written to ({exc.strerror or exc}); "
                         "choose another folder or change its permissions") from None
    return folder


@contextlib.contextmanager
def output_folder(folder: Path, what: str = "--out") -> Iterator[Path]:
    """:func:`check_output_folder`, and if the stage then fails, remove the folder again when
    this call created it and it is still empty: a failed run leaves nothing behind."""
    folder = Path(folder)
    existed = folder.exists()
    try:
        check_output_folder(folder, what)
        yield folder
    except BaseException:
        if not existed:
            with contextlib.suppress(OSError):
                folder.rmdir()  # only if empty
        raise


def refuse_existing(path: Path, overwrite: bool) -> None:
    """Refuse to replace an earlier result unless the caller said so."""
    if Path(path).exists() and not overwrite:
        raise FileExistsError(f"{path} exists (an earlier run); choose another output folder "
                              "or allow overwriting (--overwrite)")
