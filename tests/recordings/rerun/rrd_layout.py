"""What a person sees when Rerun opens an ``.rrd``: its blueprint's views, read back from the
file, checked against the entities the recording holds.

:func:`layout_problems` lists, for the file's blueprint:

- a second blueprint (the web viewer opens on the first it reads, which need not be the last
  one sent);
- every entity a ``Spatial3DView``'s contents match that is neither 3D nor under a pinhole (the
  viewer reports "2D visualizers require a pinhole ancestor to be shown in a 3D view", or has
  nothing to draw for it);
- every view that matches no entity with data it can show (the viewer says "No data
  available").

Contents are Rerun's query expressions (``+ path``, ``- path``, ``path/**``, ``$origin``): of
the rules that match an entity the most specific wins (a longer path; an exact path over a
subtree at the same path), of equally specific ones the last; no rule, no match.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import rerun.chunk as rr_chunk

#: Archetypes that a 3D view draws in the world.
THREE_D = frozenset({
    "Transform3D", "Pinhole", "ViewCoordinates", "Boxes3D", "Ellipsoids3D", "Cylinders3D",
    "Capsules3D", "Asset3D", "Mesh3D", "Points3D", "LineStrips3D", "Arrows3D",
    "InstancePoses3D", "CoordinateFrame", "TransformAxes3D"})
#: Archetypes that a 2D view draws (in 3D only under a pinhole).
TWO_D = frozenset({"Image", "EncodedImage", "DepthImage", "SegmentationImage", "Boxes2D",
                   "Points2D", "LineStrips2D", "Arrows2D", "VideoFrameReference",
                   "AssetVideo"})
#: What each view class shows; a 3D view also shows 2D archetypes under a pinhole.
SHOWS = {"2D": TWO_D, "3D": THREE_D, "TimeSeries": frozenset({"Scalars"}),
         "TextLog": frozenset({"TextLog"}), "TextDocument": frozenset({"TextDocument"}),
         "BarChart": frozenset({"BarChart", "Tensor"})}
#: Archetypes that are no data to show: clearing, the recording's own properties.
NOT_DATA = frozenset({"Clear", "RecordingInfo"})


@dataclass(frozen=True)
class View:
    """One view of a blueprint: its class (``2D``, ``3D``, ``TimeSeries`` ...), name, origin,
    contents (query expressions) and the entities it starts with hidden."""

    kind: str
    name: str
    origin: str
    contents: tuple[str, ...]
    hidden: frozenset[str] = frozenset()


def entities(path: str | Path) -> dict[str, set[str]]:
    """The archetypes each entity of the recording holds data of, by entity path (no leading
    slash; ``""`` for the root)."""
    out: dict[str, set[str]] = defaultdict(set)
    for chunk in rr_chunk.RrdReader(path).store().stream():
        names = chunk.to_record_batch().schema.names
        found = {n.split(":", 1)[0] for n in names if ":" in n} - NOT_DATA
        if found:
            out[chunk.entity_path.strip("/")] |= found
    return dict(out)


def blueprint_views(path: str | Path) -> list[View]:
    """The views of the blueprint of ``path``; of several (each a store of its own in the
    file), the one sent last."""
    reader = rr_chunk.RrdReader(path)
    latest, chosen = None, None
    for store in reader.blueprints():
        chunks = [(chunk.entity_path.strip("/"), chunk.to_record_batch().to_pylist())
                  for chunk in reader.store(store=store).stream()]
        when = max(row["log_time"] for _, rows in chunks for row in rows if "log_time" in row)
        if latest is None or when > latest:
            latest, chosen = when, chunks
    if chosen is None:
        return []
    heads: dict[str, dict] = {}
    queries: dict[str, tuple[str, ...]] = {}
    hidden: dict[str, set[str]] = defaultdict(set)
    for entity, rows in chosen:
        for row in rows:
            if row.get("ViewBlueprint:class_identifier"):
                heads[entity] = row
            if row.get("ViewContents:query") is not None:
                queries[entity.removesuffix("/ViewContents")] = tuple(row["ViewContents:query"])
            if row.get("EntityBehavior:visible") == [False]:
                # view/<id>/ViewContents/overrides/<entity>/visualizers
                view, _, rest = entity.partition("/ViewContents/overrides/")
                hidden[view].add(rest.removesuffix("/visualizers"))
    return [View(kind=row["ViewBlueprint:class_identifier"][0],
                 name=(row.get("ViewBlueprint:display_name") or [""])[0],
                 origin=row["ViewBlueprint:space_origin"][0].strip("/"),
                 contents=queries.get(entity, ("$origin/**",)),
                 hidden=frozenset(hidden.get(entity, ())))
            for entity, row in heads.items()]


def matches(entity: str, origin: str, contents: tuple[str, ...]) -> bool:
    """Whether ``entity`` is in a view at ``origin`` whose contents are ``contents``."""
    best: tuple[int, int] | None = None
    included = False
    for expr in contents:
        expr = expr.strip()
        include = not expr.startswith("-")
        expr = expr.lstrip("+-").strip().replace("$origin", "/" + origin).strip("/")
        subtree = expr.endswith("**")
        path = expr.removesuffix("**").strip("/")
        hit = entity == path or (subtree and (not path or entity.startswith(path + "/")))
        if not hit:
            continue
        specificity = (len(path.split("/")) if path else 0, 0 if subtree else 1)
        if best is None or specificity >= best:
            best, included = specificity, include
    return included


def under_pinhole(entity: str, held: dict[str, set[str]]) -> bool:
    """Whether ``entity`` or one of its ancestors holds a Pinhole."""
    parts = entity.split("/") if entity else []
    return any("Pinhole" in held.get("/".join(parts[:k]), ()) for k in range(len(parts) + 1))


def layout_problems(path: str | Path) -> list[str]:
    """What a person would see wrong in ``path``'s blueprint (empty if nothing): a 3D view
    that holds an entity it cannot place, a view without data, several blueprints or none."""
    held = entities(path)
    views = blueprint_views(path)
    if not views:
        return [f"{Path(path).name}: no blueprint"]
    problems = []
    n = len(rr_chunk.RrdReader(path).blueprints())
    if n > 1:
        problems.append(f"{Path(path).name}: {n} blueprints; the viewer may open on any")
    for view in views:
        shown = {e: a for e, a in held.items() if matches(e, view.origin, view.contents)}
        if view.kind == "3D":
            for e, archetypes in sorted(shown.items()):
                if not archetypes & THREE_D and not under_pinhole(e, held):
                    problems.append(f"3D view {view.name!r} holds /{e} "
                                    f"({', '.join(sorted(archetypes))}): neither 3D nor under "
                                    "a pinhole")
        wanted = SHOWS.get(view.kind, frozenset())
        drawn = [e for e, a in shown.items()
                 if a & wanted or (view.kind == "3D" and a & TWO_D and under_pinhole(e, held))]
        if not drawn:
            problems.append(f"{view.kind} view {view.name!r} at /{view.origin} "
                            f"({', '.join(view.contents)}) shows no data")
    return problems
