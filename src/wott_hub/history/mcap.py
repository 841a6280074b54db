"""Export a range of history as MCAP for Foxglove: every record, and Foxglove's own messages.

Contract (``docs/history.md``, ``docs/robotics.md``):
- one channel per Thing and affordance, topic ``/<thing>/events/<name>`` or
  ``/<thing>/properties/<name>``, message encoding ``json``, its schema (encoding
  ``jsonschema``) the affordance's data schema from the Thing's recorded TD;
- every record is one message whose ``data`` is the payload exactly as subscribers got it,
  ``log_time`` = ``publish_time`` = the recorded time (ns), ``sequence`` = the record's
  seq (mod 2**32, MCAP's field is 32 bits); a channel's metadata names thing, kind and affordance;
- with ``scene`` (the default), what ``robotics.mapping`` makes of the records in Foxglove's
  well-known schemas (protobuf): the skin's mesh, its deformation and the contacts as
  ``foxglove.SceneUpdate`` (scenes at most ``scene_hz`` a second, the latest state always drawn),
  actions as ``foxglove.Log``, and ``foxglove.FrameTransforms`` on ``/tf`` so Foxglove's 3D panel
  places every skin with no frame set by hand; the mesh and the transforms again every
  ``MESH_EVERY_S`` so that a seek finds them. The same channels and bytes the live Foxglove
  endpoint sends (``robotics/live.py``);
- one metadata record ``wott-hub`` per Thing with its id, title, family and TD.

Chunks are zstd-compressed (the ``mcap`` writer's default).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import IO

from wott_hub.errors import NotFound
from wott_hub.robotics.channel import Channel, Out
from wott_hub.robotics.mapping import MESH_EVERY_S, FleetMapping
from wott_hub.robotics.names import raw_topic

from .merge import merged_pages
from .storage import StorageReader

__all__ = ["CHECK_EVERY", "ExportSummary", "export_mcap", "topic_of"]

CHECK_EVERY = 4096
"""Records between two calls of an export's ``check`` (a few ms of work)."""

topic_of = raw_topic
"""A record's channel: ``/<thing>/events/<name>`` or ``/<thing>/properties/<name>``."""



@dataclass
class ExportSummary:
    records: int = 0
    scene_messages: int = 0  # every Foxglove message beyond the records (scenes, logs, transforms)
    topics: list[str] = field(default_factory=list)


def export_mcap(reader: StorageReader, out: IO[bytes], things: Sequence[str], *,
                t_from_ns: int | None = None, t_to_ns: int | None = None, names: list[str] | None = None,
                scene: bool = True, scene_hz: float = 30.0, color_max_mm: float = 2.0,
                check: Callable[[], None] | None = None) -> ExportSummary:
    """Write the records of ``things`` in [t_from, t_to] (time order across Things) to ``out``.

    ``NotFound`` names a Thing that was never recorded. ``check`` is called between pages and every
    ``CHECK_EVERY`` records: whatever it raises ends the export (the hub's: its client left)."""
    from mcap.writer import Writer

    things = list(dict.fromkeys(things))  # a Thing named twice is exported once (issue 48)
    infos = {}
    for thing in things:
        info = reader.thing_info(thing)
        if info is None:
            raise NotFound(f"no recorded device {thing!r} (see `wott-hub history list`)")
        infos[thing] = info
    writer = Writer(out)
    writer.start(profile="", library="wott-hub")
    fleet = FleetMapping("foxglove", scene_hz=scene_hz, color_max_mm=color_max_mm)
    for thing, info in infos.items():
        writer.add_metadata("wott-hub", {"thing": thing, "title": info["title"], "family": info["family"],
                                         "td": json.dumps(info["td"] or {})})
        fleet.add(thing, info["td"], info["static_values"])
    summary = ExportSummary()
    schemas: dict[tuple[str, str, bytes], int] = {}
    channels: dict[Channel, int] = {}

    def channel_id(ch: Channel) -> int:
        cid = channels.get(ch)
        if cid is None:
            key = (ch.schema_name, ch.schema_encoding, ch.schema)
            sid = schemas.get(key)
            if sid is None:
                sid = schemas[key] = writer.register_schema(name=ch.schema_name, encoding=ch.schema_encoding,
                                                            data=ch.schema)
            cid = channels[ch] = writer.register_channel(topic=ch.topic, message_encoding=ch.encoding,
                                                         schema_id=sid, metadata=dict(ch.metadata))
        return cid

    def emit(outs: list[Out]) -> None:
        for o in outs:
            writer.add_message(channel_id(o.channel), o.t_ns, o.payload, o.t_ns)
        summary.scene_messages += len(outs)

    next_tf = -(2**62)
    tf_ns = int(MESH_EVERY_S * 1e9)
    for records in merged_pages(reader, list(things), t_from_ns, t_to_ns, names):
        for i, rec in enumerate(records):
            if check is not None and i % CHECK_EVERY == 0:
                check()
            t = rec.t_ns
            if scene:
                if t >= next_tf:
                    tf = fleet.transforms(t)
                    if tf is not None:
                        emit([tf])
                    next_tf = t + tf_ns
                emit(fleet.due(t))
            for o in fleet.raw(rec):
                writer.add_message(channel_id(o.channel), t, o.payload, t, sequence=rec.seq & 0xFFFFFFFF)
            summary.records += 1
            if scene:
                emit(fleet.things[rec.thing].record(rec))
    if scene:
        emit(fleet.due(2**62))  # the latest state of every scene, drawn at its slot
    writer.finish()  # type: ignore[no-untyped-call]  # mcap's Writer.finish is unannotated
    summary.topics = sorted({ch.topic for ch in channels if ch.encoding == "json"})
    return summary
