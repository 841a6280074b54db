"""Export a range of history as MCAP, the robotics recording format Foxglove and rosbag2 read.

Contract (``docs/history.md``):
- one channel per Thing and affordance, topic ``/<thing>/events/<name>`` or
  ``/<thing>/properties/<name>``, message encoding ``json``, its schema (encoding
  ``jsonschema``) the affordance's data schema from the Thing's recorded TD;
- every record is one message whose ``data`` is the payload exactly as subscribers got it,
  ``log_time`` = ``publish_time`` = the recorded time (ns), ``sequence`` = the record's
  seq (mod 2**32, MCAP's field is 32 bits); a channel's metadata names thing, kind and affordance;
- for a Tactile Thing (``skinNodes`` recorded), ``/<thing>/scene/skin`` carries the rest mesh
  and ``/<thing>/scene/deformation`` the deformed triangles coloured by intensity, as
  ``foxglove.SceneUpdate`` messages (JSON, frame ``<thing>``, metres) so Foxglove's 3D panel
  shows the skin; the mesh again every ``MESH_EVERY_S`` so that a seek shows it, the
  deformation at most ``scene_hz`` times a second (the latest packet wins);
- one metadata record ``wott-hub`` per Thing with its id, title, family and TD.

Chunks are zstd-compressed (the ``mcap`` writer's default).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import IO, Any

import numpy as np

from wott_hub.errors import NotFound
from wott_hub.events.record import KIND_EVENT, KIND_NAMES, KIND_PROPERTY

from .merge import merged_pages
from .storage import StorageReader

__all__ = ["CHECK_EVERY", "MESH_EVERY_S", "SCENE_UPDATE_SCHEMA", "ExportSummary", "export_mcap", "topic_of"]

MESH_EVERY_S = 60.0
CHECK_EVERY = 4096
"""Records between two calls of an export's ``check`` (a few ms of work)."""
SKIN_EVENT = "skinDeformedDetection"

_TIME = {"type": "object", "title": "time",
         "properties": {"sec": {"type": "integer", "minimum": 0},
                        "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}}}
_VEC = {"type": "object", "properties": {k: {"type": "number"} for k in "xyz"}}
_COLOR = {"type": "object", "title": "foxglove.Color", "properties": {k: {"type": "number"} for k in "rgba"}}
_POSE = {"type": "object", "title": "foxglove.Pose",
         "properties": {"position": {**_VEC, "title": "foxglove.Vector3"},
                        "orientation": {"type": "object", "title": "foxglove.Quaternion",
                                        "properties": {k: {"type": "number"} for k in "xyzw"}}}}
_TRIANGLES = {
    "type": "object", "title": "foxglove.TriangleListPrimitive",
    "properties": {
        "pose": _POSE,
        "points": {"type": "array", "items": {**_VEC, "title": "foxglove.Point3"}},
        "color": _COLOR,
        "colors": {"type": "array", "items": _COLOR},
        "indices": {"type": "array", "items": {"type": "integer", "minimum": 0}},
    },
}
SCENE_UPDATE_SCHEMA: dict[str, Any] = {
    "title": "foxglove.SceneUpdate",
    "description": "An update to the entities displayed in a 3D scene (the fields this export writes, "
                   "named and typed as Foxglove's published schema)",
    "type": "object",
    "properties": {
        "deletions": {"type": "array", "items": {"type": "object", "properties": {
            "timestamp": _TIME, "type": {"type": "integer"}, "id": {"type": "string"}}}},
        "entities": {"type": "array", "items": {
            "type": "object", "title": "foxglove.SceneEntity",
            "properties": {
                "timestamp": _TIME,
                "frame_id": {"type": "string"},
                "id": {"type": "string"},
                "lifetime": {"type": "object", "title": "duration", "properties": {
                    "sec": {"type": "integer"}, "nsec": {"type": "integer"}}},
                "frame_locked": {"type": "boolean"},
                "metadata": {"type": "array", "items": {"type": "object", "properties": {
                    "key": {"type": "string"}, "value": {"type": "string"}}}},
                "triangles": {"type": "array", "items": _TRIANGLES},
            }}},
    },
}
_IDENTITY_POSE = {"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0,
                                                                              "w": 1.0}}


_POSE_TEXT = json.dumps(_IDENTITY_POSE, separators=(",", ":"))


def topic_of(thing: str, kind: int, name: str) -> str:
    return f"/{thing}/{'properties' if kind == KIND_PROPERTY else 'events'}/{name}"


@dataclass
class ExportSummary:
    records: int = 0
    scene_messages: int = 0
    topics: list[str] = field(default_factory=list)


class _Skin:
    """A Thing's rest mesh as triangles, and the SceneUpdate of one deformation packet."""

    def __init__(self, thing: str, static: dict[str, Any], color_max_mm: float) -> None:
        nodes = static["skinNodes"]["arrayOfNodes"]
        self.thing = thing
        self.row = {int(n["nodeID"]): i for i, n in enumerate(nodes)}
        self.points = np.array([(n["nodeLocation"]["x"], n["nodeLocation"]["y"], n["nodeLocation"]["z"])
                                for n in nodes], dtype=np.float64) / 1000.0  # mm -> m (Foxglove's unit)
        tris: list[tuple[int, int, int]] = []
        for cell in (static.get("skinCells") or {}).get("arrayOfCells") or []:
            rows = [self.row[int(i)] for i in cell["connectedNodes"] if int(i) in self.row]
            tris.extend((rows[0], rows[k], rows[k + 1]) for k in range(1, len(rows) - 1))  # a fan
        self.tris = np.array(tris, dtype=np.int64).reshape(-1, 3)
        self.of_row: list[list[int]] = [[] for _ in range(len(nodes))]
        for t, tri in enumerate(self.tris.tolist()):
            for r in tri:
                self.of_row[r].append(t)
        self.scale = 1.0 / color_max_mm
        # the JSON of each point (0.1 µm) and of 256 colour levels, written once: a deformation
        # message is then joined from texts (json.dumps of nested dicts cost ~10x more)
        self.point_text = [f'{{"x":{x:.7f},"y":{y:.7f},"z":{z:.7f}}}' for x, y, z in self.points.tolist()]
        self.color_text = [f'{{"r":{x:.4f},"g":{0.25 * (1 - x):.4f},"b":{1 - x:.4f},"a":1}}'
                           for x in (i / 255 for i in range(256))]

    def _pts(self, rows: np.ndarray) -> list[dict[str, float]]:
        return [{"x": x, "y": y, "z": z} for x, y, z in self.points[rows].tolist()]

    def _head(self, entity: str, t_ns: int) -> str:
        return (f'{{"deletions":[],"entities":[{{"timestamp":{{"sec":{t_ns // 1_000_000_000},'
                f'"nsec":{t_ns % 1_000_000_000}}},"frame_id":{json.dumps(self.thing)},"id":"{entity}",'
                f'"lifetime":{{"sec":0,"nsec":0}},"frame_locked":true,'
                f'"metadata":[{{"key":"thing","value":{json.dumps(self.thing)}}}],"triangles":[')

    def _entity(self, entity: str, t_ns: int, triangles: list[dict[str, Any]]) -> dict[str, Any]:
        return {"timestamp": {"sec": t_ns // 1_000_000_000, "nsec": t_ns % 1_000_000_000},
                "frame_id": self.thing, "id": entity, "lifetime": {"sec": 0, "nsec": 0},
                "frame_locked": True, "metadata": [{"key": "thing", "value": self.thing}],
                "triangles": triangles}

    def mesh(self, t_ns: int) -> bytes:
        tri = {"pose": _IDENTITY_POSE, "points": self._pts(np.arange(len(self.points))),
               "color": {"r": 0.6, "g": 0.6, "b": 0.65, "a": 0.35}, "colors": [],
               "indices": self.tris.ravel().tolist()}
        return json.dumps({"deletions": [], "entities": [self._entity("skin", t_ns, [tri])]}).encode()

    def deformation(self, t_ns: int, packet: str) -> bytes:
        intensity: dict[int, float] = {}
        for n in json.loads(packet).get("arrayOfDeformedNodes") or []:
            row = self.row.get(int(n["deformedNodeID"]))
            if row is not None and n["deformedNodeIntensity"] > 0:
                intensity[row] = float(n["deformedNodeIntensity"])
        tris = sorted({t for r in intensity for t in self.of_row[r]})
        body = ""
        if tris:
            corners = self.tris[tris]
            rows, local = np.unique(corners, return_inverse=True)
            rows_l = rows.tolist()
            scale = 255 * self.scale
            colors = ",".join([self.color_text[min(255, int(intensity.get(r, 0.0) * scale + 0.5))]
                               for r in rows_l])
            points = ",".join([self.point_text[r] for r in rows_l])
            indices = ",".join(map(str, local.ravel().tolist()))
            body = (f'{{"pose":{_POSE_TEXT},"points":[{points}],"color":{{"r":1,"g":0,"b":0,"a":1}},'
                    f'"colors":[{colors}],"indices":[{indices}]}}')
        return (self._head("deformation", t_ns) + body + "]}]}").encode()


def _schema_of(td: dict[str, Any] | None, kind: int, name: str) -> dict[str, Any]:
    """The affordance's data schema from the TD (its forms and TD-only terms left out)."""
    aff = ((td or {}).get("events" if kind == KIND_EVENT else "properties") or {}).get(name) or {}
    schema = aff.get("data", {}) if kind == KIND_EVENT else aff
    out = {k: v for k, v in schema.items() if k not in ("forms", "observable", "uriVariables", "@type")}
    out.setdefault("type", "object")
    out["title"] = name
    return out


def export_mcap(reader: StorageReader, out: IO[bytes], things: Sequence[str], *,
                t_from_ns: int | None = None, t_to_ns: int | None = None, names: list[str] | None = None,
                scene: bool = True, scene_hz: float = 30.0, color_max_mm: float = 2.0,
                check: Callable[[], None] | None = None) -> ExportSummary:
    """Write the records of ``things`` in [t_from, t_to] (time order across Things) to ``out``.

    ``NotFound`` names a Thing that was never recorded. ``check`` is called between pages and every
    ``CHECK_EVERY`` records: whatever it raises ends the export (the hub's: its client left)."""
    from mcap.writer import Writer

    infos = {}
    for thing in things:
        info = reader.thing_info(thing)
        if info is None:
            raise NotFound(f"no recorded device {thing!r} (see `wott-hub history list`)")
        infos[thing] = info
    writer = Writer(out)
    writer.start(profile="", library="wott-hub")
    for thing, info in infos.items():
        writer.add_metadata("wott-hub", {"thing": thing, "title": info["title"], "family": info["family"],
                                         "td": json.dumps(info["td"] or {})})
    summary = ExportSummary()
    channels: dict[tuple[str, int, str], int] = {}

    def channel(thing: str, kind: int, name: str) -> int:
        key = (thing, kind, name)
        cid = channels.get(key)
        if cid is None:
            schema = _schema_of(infos[thing]["td"], kind, name)
            sid = writer.register_schema(name=f"wott.{thing}.{name}", encoding="jsonschema",
                                         data=json.dumps(schema).encode())
            cid = channels[key] = writer.register_channel(
                topic=topic_of(thing, kind, name), message_encoding="json", schema_id=sid,
                metadata={"thing": thing, "kind": KIND_NAMES.get(kind, "event"), "name": name})
        return cid

    skins: dict[str, _Skin] = {}
    scene_ids: dict[str, tuple[int, int]] = {}
    next_mesh: dict[str, int] = {}
    next_frame: dict[str, int] = {}
    pending: dict[str, tuple[int, str]] = {}  # the latest skin packet not drawn yet
    if scene:
        sid = writer.register_schema(name="foxglove.SceneUpdate", encoding="jsonschema",
                                     data=json.dumps(SCENE_UPDATE_SCHEMA).encode())
        for thing, info in infos.items():
            static = info["static_values"] or {}
            if "skinNodes" not in static:
                continue
            skins[thing] = _Skin(thing, static, color_max_mm)
            scene_ids[thing] = (
                writer.register_channel(f"/{thing}/scene/skin", "json", sid, {"thing": thing}),
                writer.register_channel(f"/{thing}/scene/deformation", "json", sid, {"thing": thing}))
    frame_ns = int(1e9 / scene_hz) if scene_hz > 0 else 0
    mesh_ns = int(MESH_EVERY_S * 1e9)
    slack = frame_ns // 10

    def draw(thing: str, t_ns: int, packet: str) -> None:
        writer.add_message(scene_ids[thing][1], t_ns, skins[thing].deformation(t_ns, packet), t_ns)
        summary.scene_messages += 1

    for records in merged_pages(reader, list(things), t_from_ns, t_to_ns, names):
        for i, rec in enumerate(records):
            if check is not None and i % CHECK_EVERY == 0:
                check()
            thing, t, kind, name, data = rec.thing, rec.t_ns, rec.kind, rec.name, rec.data
            cid = channel(thing, kind, name)
            writer.add_message(cid, t, data.encode(), t, sequence=rec.seq & 0xFFFFFFFF)
            summary.records += 1
            if thing not in skins:
                continue
            if t >= next_mesh.get(thing, -1):
                writer.add_message(scene_ids[thing][0], t, skins[thing].mesh(t), t)
                summary.scene_messages += 1
                next_mesh[thing] = t + mesh_ns
            if kind == KIND_EVENT and name == SKIN_EVENT:
                if t + slack >= next_frame.get(thing, -1):  # slack: 120 Hz at 30 Hz is every 4th
                    pending.pop(thing, None)
                    draw(thing, t, data)
                    next_frame[thing] = t + frame_ns
                else:
                    pending[thing] = (t, data)  # drawn at the end if it is the last one
    for thing, (t, data) in pending.items():
        draw(thing, t, data)
    writer.finish()  # type: ignore[no-untyped-call]  # mcap's Writer.finish is unannotated
    summary.topics = sorted(topic_of(*k) for k in channels)
    return summary
