"""Rewriting a session file atomically: into a temporary file beside it, then renamed.

:func:`rewrite_session` copies a session's messages and metadata into a new file, leaving out
some topics, changing the session record, and letting the caller add channels and messages; the
original is replaced only once the new file is complete, so an interrupted rewrite leaves it
intact. :mod:`recordings.session.perception` adds the perception topics this way, and
:func:`strip_ground_truth` turns a simulated session into what a real work cell records.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Collection
from pathlib import Path

from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from recordings.session.reader import open_session
from recordings.session.schema import (
    END_METADATA,
    PERCEPTION_METADATA,
    SESSION_METADATA,
    PerceptionTopic,
    Topic,
)

__all__ = ["rewrite_session", "strip_ground_truth"]


def rewrite_session(
    source: str | Path, target: str | Path | None = None, *, drop_topics: Collection[str] = (),
    drop_metadata: Collection[str] = (), session_update: dict[str, str] | None = None,
    add: Callable[[Writer], dict[str, str] | None] | None = None,
) -> Path:
    """Copy a session with topics left out and content added, atomically.

    Parameters
    ----------
    source : path-like
        The session file.
    target : path-like or None
        Where to write; None rewrites ``source`` in place.
    drop_topics : collection of str
        Topics whose channels and messages are not copied.
    drop_metadata : collection of str
        Metadata records not copied (the session and end records are always kept).
    session_update : dict of str -> str
        Fields to set in the ``onionsort.session`` record (values as stored: JSON strings).
    add : callable, optional
        ``add(writer)`` registers its own schemas and channels and writes its messages after
        the copy; it may return a metadata record's ``{name: {key: value}}`` to add before the
        end record.

    Returns
    -------
    Path
        The file written.
    """
    source = Path(source)
    target = source if target is None else Path(target)
    with source.open("rb") as fh:
        reader = make_reader(fh, validate_crcs=True)
        metadata = [m for m in reader.iter_metadata() if m.name not in drop_metadata]
        messages = [(sch, ch, msg) for sch, ch, msg in reader.iter_messages(log_time_order=False)
                    if ch.topic not in drop_topics]
    tmp = target.with_name(target.name + ".partial")
    try:
        with tmp.open("wb") as out:
            writer = Writer(out, compression=CompressionType.ZSTD, enable_crcs=True)
            writer.start(profile="", library="onionsort")
            for m in metadata:
                if m.name == SESSION_METADATA:
                    writer.add_metadata(m.name, {**dict(m.metadata), **(session_update or {})})
            schemas: dict[int, int] = {}
            channels: dict[int, int] = {}
            for sch, ch, msg in messages:
                if sch is not None and sch.id not in schemas:
                    schemas[sch.id] = writer.register_schema(sch.name, sch.encoding, sch.data)
                if ch.id not in channels:
                    channels[ch.id] = writer.register_channel(
                        ch.topic, ch.message_encoding, schemas.get(sch.id, 0) if sch else 0,
                        dict(ch.metadata))
                writer.add_message(channels[ch.id], log_time=msg.log_time, data=msg.data,
                                   publish_time=msg.publish_time, sequence=msg.sequence)
            added = add(writer) if add is not None else None
            for m in metadata:
                if m.name not in (SESSION_METADATA, END_METADATA):
                    writer.add_metadata(m.name, dict(m.metadata))
            for name, record in (added or {}).items():
                writer.add_metadata(name, record)
            for m in metadata:
                if m.name == END_METADATA:
                    writer.add_metadata(m.name, dict(m.metadata))
            writer.finish()
        tmp.replace(target)
    finally:
        tmp.unlink(missing_ok=True)
    return target


def strip_ground_truth(source: str | Path, target: str | Path) -> Path:
    """Write ``source`` without its ground truth (and without perception) to ``target``.

    What is left is the sensor side alone: exactly what a recording of a real work cell holds.
    The session record says ``ground_truth: false``.

    Raises
    ------
    FileExistsError
        If ``target`` exists.
    """
    if Path(target).exists():
        raise FileExistsError(f"{target} exists; choose another output")
    version = str(open_session(source).metadata.get("format_version"))
    if version == "1":
        raise ValueError(f"{source} is a format-1 session, whose only step clock is its ground "
                         "truth; record it again (format 2 has a step clock of its own)")
    return rewrite_session(source, target,
                           drop_topics=(*Topic.GROUND_TRUTH, *PerceptionTopic.ALL),
                           drop_metadata=(PERCEPTION_METADATA,),
                           session_update={"ground_truth": json.dumps(False)})
