"""rosbag2 export: an independent reader (``rosbags``, pure Python) opens the folder, deserialises
every message with the types the bag declares, and what it reads equals history: counts, stamps and
values. A second, independent CDR decoder (``mcap-ros2-support``, Foxglove's) decodes every message
from the embedded ``ros2msg`` definitions alone. The command's bad input: one line, an exit code."""

from __future__ import annotations

import json
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY, Record, encode
from wott_hub.history.rosbag2 import export_rosbag2

from .skin_records import register_device, skin_records

WOTT_HUB = str(Path(sys.executable).parent / "wott-hub")
T0 = 1_700_000_000 * 10**9


@pytest.fixture
def recorded(writer):
    """Two devices: skin packets, contacts (one with no contact, one with two), actions, a device
    action, and a property the mapping does not know (a String in the bag)."""
    recs: list[Record] = []
    for i, thing in enumerate(("pad-a", "pad-b")):
        start, n = register_device(writer, thing, shape="flat" if i == 0 else "cylinder")
        rs = skin_records(thing, start, 240, n, t0_ns=T0 + i * 3_000_000, seed=i)
        seq = rs[-1].seq
        t = rs[-1].t_ns
        for k, (kind, name, value) in enumerate([
                (KIND_EVENT, "actionDetection", "press"),
                (KIND_EVENT, "actionDetails", {"action": "press", "confidence": 0.9, "evidence": {
                    "contacts": 1, "durationS": 0.4, "speedMmPerS": 1.5}}),
                (KIND_PROPERTY, "contactInformation", {"numOfContacts": 2, "contactLocations": [
                    {"x": 1.0, "y": 2.0, "z": 3.0}, {"x": -4.0, "y": 5.5, "z": 0.0}], "contactForces": [
                    {"x": 0.1, "y": 0.0, "z": -0.5}, {"x": 0.0, "y": -0.2, "z": -0.3}]}),
                (KIND_PROPERTY, "contactInformation", {"numOfContacts": 0, "contactLocations": [],
                                                       "contactForces": []}),
                (KIND_EVENT, "deviceAction", {"device": thing, "invokedAction": "tare"}),
                (KIND_PROPERTY, "unavailableNodes", {"numOfUnavailableNodes": 1,
                                                     "arrayOfUnavailableNodes": [3]})]):
            seq += 1
            rs.append(Record(thing, seq, kind, name, t + (k + 1) * 1_000_000, encode(value)))
        recs += rs
    writer.start()
    for r in recs:
        writer.submit(r)
    assert writer.flush()
    return recs


def _read_bag(path: Path):
    from rosbags.highlevel import AnyReader

    out = []
    with AnyReader([path]) as bag:
        types = {c.topic: c.msgtype for c in bag.connections}
        for conn, t_ns, raw in bag.messages():
            out.append((conn.topic, t_ns, bag.deserialize(raw, conn.msgtype)))
        qos = {c.topic: c.ext.offered_qos_profiles for c in bag.connections}
    return out, types, qos


def _cloud(msg) -> dict[str, np.ndarray]:
    dtype = np.dtype({"names": [f.name for f in msg.fields], "formats": ["<f4" if f.datatype == 7 else "<u4"
                                                                          for f in msg.fields],
                      "offsets": [f.offset for f in msg.fields], "itemsize": msg.point_step})
    data = np.frombuffer(msg.data.tobytes(), dtype=dtype)
    return {n: data[n] for n in dtype.names}


def test_rosbags_reads_every_message_and_it_equals_history(reader, recorded, tmp_path):
    bag = tmp_path / "bag"
    summary = export_rosbag2(reader, bag, ["pad-a", "pad-b"])
    assert summary.records == len(recorded)
    assert sorted(p.name for p in bag.iterdir()) == ["bag.mcap", "metadata.yaml"]
    msgs, types, qos = _read_bag(bag)
    assert types["/tf_static"] == "tf2_msgs/msg/TFMessage"
    assert types["/pad_a/skin/deformation"] == "sensor_msgs/msg/PointCloud2"
    assert types["/pad_a/skin/mesh"] == "visualization_msgs/msg/MarkerArray"
    assert types["/pad_b/contacts/markers"] == "visualization_msgs/msg/MarkerArray"
    assert types["/pad_b/contacts/wrench"] == "geometry_msgs/msg/WrenchStamped"
    assert types["/pad_a/actions"] == "rcl_interfaces/msg/Log"
    assert types["/pad_a/properties/unavailableNodes"] == "std_msgs/msg/String"
    from rosbags.interfaces import QosDurability

    assert qos["/tf_static"][0].durability == QosDurability.TRANSIENT_LOCAL
    assert qos["/pad_a/skin/deformation"][0].durability == QosDurability.VOLATILE
    by_topic: dict[str, list] = {}
    for topic, t_ns, msg in msgs:
        by_topic.setdefault(topic, []).append((t_ns, msg))
    (tf_t, tf), = by_topic["/tf_static"]
    assert {t.child_frame_id for t in tf.transforms} == {"pad-a", "pad-b"}
    assert all(t.header.frame_id == "wott_hub" and t.transform.rotation.w == 1.0 for t in tf.transforms)
    assert tf_t == min(r.t_ns for r in recorded)
    for thing, ns in (("pad-a", "pad_a"), ("pad-b", "pad_b")):
        mine = [r for r in recorded if r.thing == thing]
        info = reader.thing_info(thing)
        nodes = {n["nodeID"]: n["nodeLocation"] for n in info["static_values"]["skinNodes"]["arrayOfNodes"]}
        # counts: one message per record on its topic, the mesh once (less than a minute)
        counts = Counter(r.name for r in mine)
        assert len(by_topic[f"/{ns}/skin/deformation"]) == counts["skinDeformedDetection"]
        assert len(by_topic[f"/{ns}/contacts/markers"]) == counts["contactInformation"]
        assert len(by_topic[f"/{ns}/contacts/wrench"]) == counts["contactInformation"]
        assert len(by_topic[f"/{ns}/actions"]) == 3
        assert len(by_topic[f"/{ns}/skin/mesh"]) == 1
        (mesh_t, mesh), = by_topic[f"/{ns}/skin/mesh"]
        tri = mesh.markers[0]
        assert tri.type == 11 and tri.header.frame_id == thing and len(tri.points) % 3 == 0
        cells = info["static_values"]["skinCells"]["numOfCells"]
        assert len(tri.points) >= 3 * cells  # quads as two triangles
        # values and stamps, record by record
        skins = [r for r in mine if r.name == "skinDeformedDetection"]
        for r, (t_ns, msg) in zip(skins, by_topic[f"/{ns}/skin/deformation"], strict=True):
            packet = json.loads(r.data)
            assert t_ns == r.t_ns
            assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == packet["timeStamp"]
            assert msg.header.frame_id == thing
            cloud = _cloud(msg)
            ids = [n["deformedNodeID"] for n in packet["arrayOfDeformedNodes"]]
            assert cloud["node_id"].tolist() == ids
            want = np.array([n["deformedNodeIntensity"] for n in packet["arrayOfDeformedNodes"]]) / 1000
            np.testing.assert_allclose(cloud["intensity"], want, rtol=1e-6)
            rest = np.array([[nodes[i][k] for k in "xyz"] for i in ids]) / 1000
            np.testing.assert_allclose(np.column_stack([cloud["x"], cloud["y"], cloud["z"]]), rest, atol=1e-7)
        contacts = [r for r in mine if r.name == "contactInformation"]
        shown = 0  # arrows on display before each message
        for r, (t_ns, arr), (t2, wrench) in zip(contacts, by_topic[f"/{ns}/contacts/markers"],
                                                by_topic[f"/{ns}/contacts/wrench"], strict=True):
            value = json.loads(r.data)
            assert t_ns == t2 == r.t_ns
            arrows = [m for m in arr.markers if m.action == 0]  # ADD, ids 0..n-1; DELETE the rest shown
            assert [m.id for m in arrows] == list(range(value["numOfContacts"]))
            assert [m.id for m in arr.markers if m.action == 2] == list(range(len(arrows), shown))
            shown = len(arrows)
            force = np.zeros(3)
            torque = np.zeros(3)
            for m, loc, f in zip(arrows, value["contactLocations"], value["contactForces"], strict=True):
                head = np.array([m.points[1].x, m.points[1].y, m.points[1].z])
                tail = np.array([m.points[0].x, m.points[0].y, m.points[0].z])
                fv = np.array([f[k] for k in "xyz"])
                np.testing.assert_allclose(head, [loc[k] / 1000 for k in "xyz"], atol=1e-12)
                np.testing.assert_allclose(head - tail, fv * 0.02, atol=1e-12)  # along the force, 2 cm/N
                force += fv
                torque += np.cross(head, fv)
            w = wrench.wrench
            np.testing.assert_allclose([w.force.x, w.force.y, w.force.z], force, atol=1e-12)
            np.testing.assert_allclose([w.torque.x, w.torque.y, w.torque.z], torque, atol=1e-12)
        logs = [(t, m.msg, m.level, m.name) for t, m in by_topic[f"/{ns}/actions"]]
        acts = [r for r in mine if r.name in ("actionDetection", "actionDetails", "deviceAction")]
        assert [(t, lvl, name) for t, _, lvl, name in logs] == [
            (r.t_ns, 10 if r.name == "actionDetails" else 20, thing) for r in acts]
        assert logs[0][1] == "press" and logs[1][1].startswith("press (confidence 0.9; contacts 1")
        (t_u, s), = by_topic[f"/{ns}/properties/unavailableNodes"]
        unavailable = next(r for r in mine if r.name == "unavailableNodes")
        assert (t_u, s.data) == (unavailable.t_ns, unavailable.data)
    # every message, whatever its topic, is one of these: nothing in the bag that history lacks
    assert len(msgs) == summary.messages


def test_an_independent_cdr_decoder_reads_every_message(reader, recorded, tmp_path):
    """Foxglove's ROS 2 decoder (mcap-ros2-support) from the schemas embedded in the bag alone."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    bag = tmp_path / "bag"
    summary = export_rosbag2(reader, bag, ["pad-a"])
    with (bag / "bag.mcap").open("rb") as f:
        mcap = make_reader(f, decoder_factories=[DecoderFactory()])
        assert mcap.get_header().profile == "ros2"
        decoded = [(schema.encoding, ch.message_encoding, ch.topic, msg)
                   for schema, ch, _, msg in mcap.iter_decoded_messages()]
    assert len(decoded) == summary.messages
    assert {(s, e) for s, e, _, _ in decoded} == {("ros2msg", "cdr")}
    first = next(m for _, _, topic, m in decoded if topic == "/pad_a/skin/deformation")
    assert first.header.frame_id == "pad-a" and [f.name for f in first.fields] == [
        "x", "y", "z", "intensity", "node_id"]


def test_a_range_and_a_name_filter(reader, recorded, tmp_path):
    lo = T0 + 1_000_000_000
    bag = tmp_path / "late"
    out = export_rosbag2(reader, bag, ["pad-a"], t_from_ns=lo, names=["contactInformation"])
    want = [r for r in recorded if r.thing == "pad-a" and r.t_ns >= lo and r.name == "contactInformation"]
    assert out.records == len(want) and want
    msgs, types, _ = _read_bag(bag)
    assert {t for t, _, _ in msgs} == {"/tf_static", "/pad_a/skin/mesh", "/pad_a/contacts/markers",
                                       "/pad_a/contacts/wrench"}


def test_no_record_in_the_range_or_an_existing_folder_leaves_nothing(reader, recorded, tmp_path):
    from wott_hub.errors import InvalidInput, NotFound

    with pytest.raises(InvalidInput, match="no records"):
        export_rosbag2(reader, tmp_path / "empty", ["pad-a"], t_from_ns=T0 + 10**12)
    assert not (tmp_path / "empty").exists()
    (tmp_path / "there").mkdir()
    with pytest.raises(InvalidInput, match="exists"):
        export_rosbag2(reader, tmp_path / "there", ["pad-a"])
    with pytest.raises(NotFound, match="nope"):
        export_rosbag2(reader, tmp_path / "x", ["nope"])


def _db(engine) -> str:
    db = engine.url.render_as_string(hide_password=False)
    return db.removeprefix("sqlite:///")


def test_the_command_writes_a_bag_and_refuses_bad_input_in_one_line(engine, recorded, tmp_path):
    db = _db(engine)
    bag = tmp_path / "cli-bag"
    base = [WOTT_HUB, "history", "export", "--format", "rosbag2", "--database", db]
    done = subprocess.run([*base, "--device", "pad-a", "--device", "pad-b", "-o", str(bag)],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stderr.strip().splitlines()[-1] == f"{len(recorded)} records"
    assert (bag / "metadata.yaml").exists()
    cases = {  # what was wrong -> (exit code, a word the one line must say)
        "unknown device": ([*base, "--device", "nope", "-o", str(tmp_path / "a")], 3, "nope"),
        "empty range": ([*base, "--device", "pad-a", "--from", "2100-01-01T00:00:00Z", "-o",
                         str(tmp_path / "b")], 2, "no records"),
        "existing folder": ([*base, "--device", "pad-a", "-o", str(bag)], 2, "exists"),
        "no output": ([*base, "--device", "pad-a"], 2, "--output"),
    }
    for what, (cmd, code, word) in cases.items():
        bad = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
        lines = bad.stderr.strip().splitlines()
        assert (bad.returncode, len(lines)) == (code, 1), (what, bad.stderr)
        assert word in lines[0] and "Traceback" not in bad.stderr, (what, bad.stderr)
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()
