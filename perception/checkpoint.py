"""Checkpoint files of every model here: a ``torch.save`` of a dict whose entries each model
names (its configuration under ``config``), written to ``NAME.partial`` and renamed when whole,
read onto the CPU with ``weights_only`` (no code of the file's choosing runs), or its
configuration alone without torch (:func:`checkpoint_config`: this module loads torch only when
it saves or loads).
"""

from __future__ import annotations

import collections
import io
import json
import pickle
import zipfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

__all__ = ["checkpoint_config", "load_checkpoint", "save_checkpoint", "write_json"]

T = TypeVar("T")


@contextmanager
def _replacing(path: Path | str) -> Iterator[Path]:
    """A temporary name to write ``path`` to, renamed to ``path`` when the block succeeds."""
    tmp = Path(path).with_name(Path(path).name + ".partial")
    try:
        yield tmp
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)


def save_checkpoint(path: Path | str, **entries: Any) -> Path:
    """Write ``entries`` to ``path``; a module among them as its state dict on the CPU."""
    import torch

    doc = {k: ({n: t.detach().cpu() for n, t in v.state_dict().items()}
               if isinstance(v, torch.nn.Module) else v) for k, v in entries.items()}
    with _replacing(path) as tmp:
        torch.save(doc, tmp)
    return Path(path)


def load_checkpoint(path: Path | str, what: str,
                    build: Callable[[dict], T] = lambda doc: doc) -> T:
    """``build`` of the checkpoint at ``path``: FileNotFoundError ``no {what} at {path}``
    without a file, ValueError ``{path} is not a {what} (...)`` where it is no checkpoint, is
    truncated, or ``build`` fails on it (another model's)."""
    import torch

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no {what} at {path}")
    try:
        return build(torch.load(path, map_location="cpu", weights_only=True))
    except Exception as exc:
        article = "an" if what[0] in "aeiou" else "a"
        raise ValueError(f"{path} is not {article} {what} ({exc})") from None


def write_json(path: Path | str, doc: Any) -> Path:
    """Write ``doc`` as JSON (indent 1) to ``path`` through a temporary name."""
    with _replacing(path) as tmp:
        tmp.write_text(json.dumps(doc, indent=1))
    return Path(path)


def _left_out(*args, **kwargs) -> None:
    """What a tensor, or any other torch object, becomes in :func:`checkpoint_config`."""
    return None


class _ConfigReader(pickle.Unpickler):
    """A checkpoint's pickle with its tensors left out: torch's types become
    :func:`_left_out`, storages None, and any type but ``OrderedDict`` is refused (no code of
    the file's choosing runs)."""

    def find_class(self, module: str, name: str):
        if module == "torch" or module.startswith("torch."):
            return _left_out
        if (module, name) == ("collections", "OrderedDict"):
            return collections.OrderedDict
        raise pickle.UnpicklingError(f"unexpected type {module}.{name} in a checkpoint")

    def persistent_load(self, pid) -> None:
        return None


def checkpoint_config(path: Path | str) -> dict:
    """The ``config`` of a checkpoint that ``torch.save`` wrote as ``{"config": {...}, ...}``
    (every model here), read without loading torch (:class:`_ConfigReader`).

    Raises
    ------
    ValueError
        Where the archive holds no model configuration.
    OSError, zipfile.BadZipFile, pickle.UnpicklingError, EOFError, ...
        Where ``path`` is no readable checkpoint.
    """
    with zipfile.ZipFile(path) as archive:
        name = next((n for n in archive.namelist() if n.endswith("/data.pkl")), None)
        if name is None:
            raise ValueError(f"{path} is not a torch checkpoint (no data.pkl)")
        data = _ConfigReader(io.BytesIO(archive.read(name))).load()
    if not isinstance(data, dict) or not isinstance(data.get("config"), dict):
        raise ValueError(f"{path} holds no model configuration")
    return dict(data["config"])
