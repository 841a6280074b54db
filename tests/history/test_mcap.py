"""MCAP export: every record comes back from the ``mcap`` reader exactly, on its channel, with its
recorded time; Foxglove scene channels carry the mesh and the deformation."""

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


def test_export_round_trips_every_record_on_its_channel(reader, two_devices, tmp_path):
    path = tmp_path / "out.mcap"
    with path.open("wb") as f:
        out = export_mcap(reader, f, ["pad-a", "pad-b"])
    assert out.records == len(two_devices)
    summary, msgs, meta = _read(path)
    records = [m for m in msgs if "/scene/" not in m[0]]
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


def test_scene_channels_hold_the_mesh_and_coloured_deformation(reader, two_devices, tmp_path):
    path = tmp_path / "out.mcap"
    with path.open("wb") as f:
        out = export_mcap(reader, f, ["pad-a"], scene_hz=30.0)
    _, msgs, _ = _read(path)
    mesh = [json.loads(m[4]) for m in msgs if m[0] == "/pad-a/scene/skin"]
    deform = [(m[1], json.loads(m[4])) for m in msgs if m[0] == "/pad-a/scene/deformation"]
    assert {m[5] for m in msgs if "/scene/" in m[0]} == {"foxglove.SceneUpdate"}
    assert len(mesh) == 1  # 2.5 s of recording: the mesh once
    tri = mesh[0]["entities"][0]["triangles"][0]
    assert len(tri["points"]) == 256 and len(tri["indices"]) % 3 == 0 and max(tri["indices"]) < 256
    # 300 packets at 120 Hz drawn at 30 Hz: about a quarter, the last packet always drawn
    assert 70 <= len(deform) <= 80 and out.scene_messages == len(mesh) + len(deform)
    skins = [r for r in two_devices if r.thing == "pad-a" and r.name == "skinDeformedDetection"]
    assert deform[-1][0] == skins[-1].t_ns
    ent = deform[0][1]["entities"][0]
    assert ent["frame_id"] == "pad-a" and ent["id"] == "deformation"
    t = ent["triangles"][0]
    assert len(t["colors"]) == len(t["points"]) and len(t["indices"]) % 3 == 0
    assert any(c["r"] > 0.5 for c in t["colors"])  # coloured by intensity (up to 3 mm here)


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
    assert sum("/scene/" not in m[0] for m in msgs) == len(two_devices)
    bad = subprocess.run([c if c != "mcap" else "csv" for c in cmd], capture_output=True, text=True,
                         timeout=60)
    assert bad.returncode == 2 and "--format" in bad.stderr and "Traceback" not in bad.stderr
    no_out = subprocess.run(cmd[:9] + ["--database", db], capture_output=True, text=True, timeout=60)
    assert no_out.returncode == 2 and "--output" in no_out.stderr
