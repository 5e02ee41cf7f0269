"""Checkpoint files of every model here: a ``torch.save`` of a dict whose entries each model
names (its configuration under ``config``), written to ``NAME.partial`` and renamed when whole,
read onto the CPU with ``weights_only`` (no code of the file's choosing runs)."""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

import torch
from torch import nn

__all__ = ["load_checkpoint", "save_checkpoint", "write_json"]

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
    doc = {k: ({n: t.detach().cpu() for n, t in v.state_dict().items()}
               if isinstance(v, nn.Module) else v) for k, v in entries.items()}
    with _replacing(path) as tmp:
        torch.save(doc, tmp)
    return Path(path)


def load_checkpoint(path: Path | str, what: str,
                    build: Callable[[dict], T] = lambda doc: doc) -> T:
    """``build`` of the checkpoint at ``path``: FileNotFoundError ``no {what} at {path}``
    without a file, ValueError ``{path} is not a {what} (...)`` where it is no checkpoint, is
    truncated, or ``build`` fails on it (another model's)."""
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
