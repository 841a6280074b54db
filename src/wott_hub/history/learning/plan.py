"""Which sources and columns an export has: from each Thing's recorded TD and values, and its records.

A Thing gets a source for each stream its TD declares and history holds (``features.py``): the skin
streams where it has ``skinNodes``, contacts, touch actions, a pressure grid (its shape from a recorded
grid), each camera that has a recorded image (its size from that image). ``--action THING.PROPERTY``
adds the property's source (its length from a recorded value); ``--state KEY`` (``ID.FEATURE`` or
``FEATURE`` for every Thing that has it) flattens those features into ``observation.state``, one name an
element. Each Thing also gets ``age.<id>``: per frame, the age in seconds of the sample each of its
streams holds (-1: none yet).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from wott_hub.errors import InvalidInput, NotFound
from wott_hub.robotics.geometry import SkinGeometry

from .features import (
    GRID_EVENT,
    IMAGE_EVENT,
    CameraSource,
    ContactsSource,
    DeformationSource,
    DisplacementSource,
    Feature,
    GridSource,
    PropertySource,
    Source,
    TouchActionSource,
)

if TYPE_CHECKING:
    from ..storage import StorageReader

__all__ = ["Plan", "ThingPlan", "plan", "state_values"]


@dataclass
class ThingPlan:
    thing: str
    sources: list[Source] = field(default_factory=list)
    nodes: list[int] = field(default_factory=list)  # skinNodes ids, in the order of the N axis

    @property
    def age(self) -> Feature:
        names = [s.age for s in self.sources]
        return Feature(f"age.{self.thing}", "float32", (len(names),), names=names, info={"unit": "s"})


@dataclass
class Plan:
    things: list[ThingPlan]
    state: list[tuple[Feature, list[str]]]  # the features flattened into observation.state, their names

    def sources(self) -> list[Source]:
        return [s for t in self.things for s in t.sources]

    def features(self) -> list[Feature]:
        """Every column in lerobot's order (the dataset's own, then its defaults come after)."""
        out = []
        if self.state:
            names = [n for _, ns in self.state for n in ns]
            out.append(Feature("observation.state", "float32", (len(names),), names=names))
        out += [f for s in self.sources() for f in s.features if f.dtype != "video"]
        out += [t.age for t in self.things]
        out += [f for s in self.sources() for f in s.features if f.dtype == "video"]
        return out

    def cameras(self) -> list[CameraSource]:
        return [s for s in self.sources() if isinstance(s, CameraSource)]


def _thing(reader: StorageReader, thing: str, end_ns: int) -> ThingPlan:
    info = reader.thing_info(thing)
    if info is None:
        raise NotFound(f"no recorded device {thing!r} (see `wott-hub history list`)")
    td = info["td"] or {}
    events, props = td.get("events") or {}, td.get("properties") or {}
    out = ThingPlan(thing)
    geom = SkinGeometry.of(thing, info["static_values"])
    if geom is not None:
        out.nodes = geom.ids.tolist()
        if "skinDeformedDetection" in events:
            out.sources.append(DeformationSource(thing, geom))
        if "skinDisplacement" in events:
            out.sources.append(DisplacementSource(thing, geom))
    if "contactInformation" in props:
        out.sources.append(ContactsSource(thing))
    if "actionDetection" in events:
        enum = ((events["actionDetection"].get("data") or {}).get("enum")) or []
        out.sources.append(TouchActionSource(thing, list(enum)))
    if GRID_EVENT in events and (grids := reader.last_at(thing, GRID_EVENT, end_ns)):
        d = json.loads(grids[0].data)
        out.sources.append(GridSource(thing, int(d["rows"]), int(d["cols"])))
    if IMAGE_EVENT in events:
        for camera, (h, w) in sorted(_cameras(reader, thing, end_ns).items()):
            if h and w:
                out.sources.append(CameraSource(thing, camera, h, w))
    return out


def _cameras(reader: StorageReader, thing: str, end_ns: int, look: int = 64) -> dict[str, tuple[int, int]]:
    """The cameras among the ``look`` last images before ``end_ns``, each with the (height, width) of its
    last one: read back 4 at a time (an image is ~0.5 MB: 64 at once were 100 MB at the export's start)."""
    seen: dict[str, tuple[int, int]] = {}
    done: set[int] = set()
    t = end_ns
    while len(done) < look:
        recs = [r for r in reader.last_at(thing, IMAGE_EVENT, t, limit=4) if r.seq not in done]
        for rec in recs:
            d = json.loads(rec.data)
            seen.setdefault(str(d.get("camera")), (int(d.get("height", 0)), int(d.get("width", 0))))
            done.add(rec.seq)
        if not recs:
            if t == end_ns or not reader.last_at(thing, IMAGE_EVENT, t - 1):
                break
            t -= 1  # 4 images at one time, all seen: on before it
        else:
            t = recs[-1].t_ns
    return seen


def _action(reader: StorageReader, spec: str, end_ns: int) -> tuple[str, PropertySource]:
    thing, dot, name = spec.rpartition(".")
    if not dot or not thing or not name:
        raise InvalidInput(f"--action {spec!r}: expected THING.PROPERTY (e.g. arm-1.jointPositions)")
    if not reader.recorded(thing):
        raise NotFound(f"--action {spec!r}: no recorded Thing {thing!r} (see `wott-hub history list`)")
    latest = reader.last_at(thing, name, end_ns)
    if not latest:
        raise InvalidInput(
            f"--action {spec!r}: {thing} has no recorded {name!r} before the end of the export"
        )
    try:
        value = json.loads(latest[0].data)
    except ValueError:
        raise InvalidInput(f"--action {spec!r}: its recorded value is not JSON") from None
    return thing, PropertySource(thing, name, value)


def _state_names(f: Feature, thing: ThingPlan) -> list[str]:
    base = f.key.removeprefix("observation.tactile.")
    if f.shape == (1,):
        return [base]
    if len(f.shape) == 1 and f.names:
        return [f"{base}.{n}" for n in f.names]
    if len(f.shape) == 1:
        return [f"{base}.{n}" for n in thing.nodes[: f.shape[0]]]
    rows, cols = f.shape
    if f.names == ["node", "axis"]:
        return [f"{base}.{n}.{a}" for n in thing.nodes[:rows] for a in "xyz"[:cols]]
    return [f"{base}.r{r}c{c}" for r in range(rows) for c in range(cols)]


def plan(
    reader: StorageReader,
    things: list[str],
    end_ns: int,
    *,
    action: str | None = None,
    state: list[str] | None = None,
) -> Plan:
    """The sources and columns of an export of ``things`` whose last episode ends at ``end_ns``."""
    plans = [_thing(reader, t, end_ns) for t in things]
    if action:
        thing, source = _action(reader, action, end_ns)
        found = next((p for p in plans if p.thing == thing), None)
        if found is None:
            found = ThingPlan(thing)
            plans.append(found)
        found.sources.append(source)
    chosen: list[tuple[Feature, list[str]]] = []
    for key in state or []:
        hits = [
            (f, p)
            for p in plans
            for s in p.sources
            for f in s.features
            if f.dtype != "video"
            and not isinstance(s, PropertySource)
            and f.key.removeprefix("observation.tactile.") in (key, f"{p.thing}.{key}")
        ]
        if not hits:
            raise InvalidInput(
                f"--state {key!r}: no such feature (ID.FEATURE or FEATURE, e.g. contact_force; "
                "docs/learning.md)"
            )
        chosen += [(f, _state_names(f, p)) for f, p in hits if all(f is not c for c, _ in chosen)]
    for p in plans:
        if not p.sources:
            raise InvalidInput(
                f"{p.thing!r} has no recorded stream a dataset can hold (skin, contacts, actions, "
                "grids, images)"
            )
    for f in (f for p in plans for s in p.sources for f in s.features):
        if f.dtype != "video" and "image" in f.key:
            raise InvalidInput(
                f"{f.key!r}: lerobot takes a feature whose name holds 'image' for a camera; rename the device"
            )
    return Plan(plans, chosen)


def state_values(p: Plan, values: dict[str, np.ndarray], frames: int) -> np.ndarray:
    """``observation.state`` of a block: the chosen features flattened, in order, as float32."""
    return np.concatenate([values[f.key].reshape(frames, -1).astype(np.float32) for f, _ in p.state], axis=1)
