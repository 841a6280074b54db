"""MCAP export: every record comes back from the ``mcap`` reader exactly, on its channel, with its
recorded time; Foxglove's own messages (protobuf, decoded here by Google's runtime from the
schemas in the file) carry the mesh, the deformation, the contacts, the actions and the frames."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader

from wott_hub.events.record import KIND_NAMES
from wott_hub.history.mcap import export_mcap, topic_of

from .skin_records import register_device, skin_records

WOTT_HUB = str(Path(sys.executable).parent / "wott-hub")


@pytest.fixture
def two_devices(writer):
    recs = []
    for i, thing in enumerate(("pad-a", "pad-b")):
        start, n = register_device(writer, thing)
        recs += skin_records(thing, start, 300, n, t0_ns=1_700_000_000 * 10**9 + i * 4_000_000, seed=i)
    writer.start()
    for r in recs:
        writer.submit(r)
    assert writer.flush()
    return recs


def _read(path):
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        msgs = [(ch.topic, m.log_time, m.publish_time, m.sequence, m.data, schema.name, schema.encoding)
                for schema, ch, m in reader.iter_messages(log_time_order=False)]
        meta = [dict(m.metadata) for m in reader.iter_metadata()]
    return summary, msgs, meta


def _decoded(path, topic):
    """(log time, message) of ``topic``, decoded from the file's own protobuf schema."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    out = []
    with open(path, "rb") as f:
        for schema, _, m in make_reader(f).iter_messages(topics=[topic]):
            pool = descriptor_pool.DescriptorPool()
            for fd in descriptor_pb2.FileDescriptorSet.FromString(schema.data).file:
                pool.Add(fd)
            cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))
            out.append((m.log_time, cls.FromString(m.data)))
    return out


def test_export_round_trips_every_record_on_its_channel(reader, two_devices, tmp_path):
    path = tmp_path / "out.mcap"
    with path.open("wb") as f:
        out = export_mcap(reader, f, ["pad-a", "pad-b"])
    assert out.records == len(two_devices)
    summary, msgs, meta = _read(path)
    records = [m for m in msgs if m[6] == "jsonschema"]
    expected = sorted(two_devices, key=lambda r: r.t_ns)  # one time base across the two devices
    assert [(m[0], m[1], m[2], m[3], m[4]) for m in records] == [
        (topic_of(r.thing, r.kind, r.name), r.t_ns, r.t_ns, r.seq, r.data.encode()) for r in expected]
    assert {m[6] for m in records} == {"jsonschema"}
    channels = {c.topic: c for c in summary.channels.values()}
    skin = channels["/pad-a/events/skinDeformedDetection"]
    assert skin.message_encoding == "json" and skin.metadata == {"thing": "pad-a", "kind": "event",
                                                                "name": "skinDeformedDetection"}
    schema = json.loads(summary.schemas[skin.schema_id].data)
    assert schema["type"] == "object" and "arrayOfDeformedNodes" in schema["properties"]
    contact = json.loads(summary.schemas[channels["/pad-b/properties/contactInformation"].schema_id].data)
    assert "contactLocations" in contact["properties"]
    assert {m["thing"] for m in meta} == {"pad-a", "pad-b"}
    assert json.loads(meta[0]["td"])["events"]["skinDeformedDetection"]
    assert KIND_NAMES[two_devices[1].kind] == "property"


def test_foxglove_channels_hold_the_mesh_deformation_contacts_and_frames(reader, two_devices, tmp_path):
    path = tmp_path / "out.mcap"
    with path.open("wb") as f:
        out = export_mcap(reader, f, ["pad-a"], scene_hz=30.0)
    _, msgs, _ = _read(path)
    schemas = {m[0]: (m[5], m[6]) for m in msgs if m[6] != "jsonschema"}
    assert schemas == {"/tf": ("foxglove.FrameTransforms", "protobuf"),
                       "/pad-a/scene/skin": ("foxglove.SceneUpdate", "protobuf"),
                       "/pad-a/scene/deformation": ("foxglove.SceneUpdate", "protobuf"),
                       "/pad-a/scene/contacts": ("foxglove.SceneUpdate", "protobuf")}
    (_, tf), = _decoded(path, "/tf")
    assert [(t.parent_frame_id, t.child_frame_id, t.rotation.w) for t in tf.transforms] == [
        ("wott_hub", "pad-a", 1.0)]
    mesh = _decoded(path, "/pad-a/scene/skin")
    assert len(mesh) == 1  # 2.5 s of recording: the mesh once
    tri = mesh[0][1].entities[0].triangles[0]
    assert len(tri.points) == 256 and len(tri.indices) % 3 == 0 and max(tri.indices) < 256
    deform = _decoded(path, "/pad-a/scene/deformation")
    # 300 packets at 120 Hz drawn at 30 Hz: about a quarter, the last packet always drawn
    assert 70 <= len(deform) <= 80
    skins = [r for r in two_devices if r.thing == "pad-a" and r.name == "skinDeformedDetection"]
    last = deform[-1][1].entities[0].timestamp
    assert last.seconds * 10**9 + last.nanos == skins[-1].t_ns
    ent = deform[0][1].entities[0]
    assert ent.frame_id == "pad-a" and ent.id == "deformation"
    t = ent.triangles[0]
    assert len(t.colors) == len(t.points) and len(t.indices) % 3 == 0
    assert any(c.r > 0.5 for c in t.colors)  # coloured by intensity (up to 3 mm here)
    arrows = _decoded(path, "/pad-a/scene/contacts")
    assert arrows and all(len(a.entities[0].arrows) == 1 for _, a in arrows)
    a = arrows[0][1].entities[0].arrows[0]
    # 0.25 N along -z, ending at the contact point (x = 0 mm, y = 1 mm): tail 5 mm above it
    assert (round(a.pose.position.x, 6), round(a.pose.position.y, 6), round(a.pose.position.z, 6)) == (
        0.0, 0.001, 0.005)
    assert round(a.shaft_length + a.head_length, 6) == 0.005
    assert out.scene_messages == len(msgs) - out.records


def test_cli_exports_mcap_and_names_a_bad_format(engine, two_devices, tmp_path):
    db = engine.url.render_as_string(hide_password=False)
    if db.startswith("sqlite:///"):
        db = db.removeprefix("sqlite:///")
    path = tmp_path / "cli.mcap"
    cmd = [WOTT_HUB, "history", "export", "--device", "pad-a", "--device", "pad-b",
           "--format", "mcap", "-o", str(path), "--database", db]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    _, msgs, _ = _read(path)
    assert sum(m[6] == "jsonschema" for m in msgs) == len(two_devices)
    bad = subprocess.run([c if c != "mcap" else "csv" for c in cmd], capture_output=True, text=True,
                         timeout=60)
    assert bad.returncode == 2 and "--format" in bad.stderr and "Traceback" not in bad.stderr
    no_out = subprocess.run(cmd[:9] + ["--database", db], capture_output=True, text=True, timeout=60)
    assert no_out.returncode == 2 and "--output" in no_out.stderr
