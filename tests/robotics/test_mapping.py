"""The one mapping, unit by unit: names, frames, the scene throttle, payloads it cannot read, and
issue 29's displacement field, camera images and taxel grids (records made here by hand in the
shapes that issue gives), each in both encodings and read back: Foxglove's by Google's protobuf
runtime, ROS 2's by ``rosbags``' CDR deserialiser."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wott_hub.errors import InvalidInput
from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY, Record, encode
from wott_hub.robotics.geometry import frame_pose
from wott_hub.robotics.mapping import FleetMapping, Throttle
from wott_hub.robotics.names import ros_namespaces, ros_token
from wott_hub.robotics.raw_signals import ImageFrame, TaxelGrid

from .foxglove_proto import decode


@pytest.fixture(scope="module")
def pad():
    """The flat example pad's TD and static values (its mesh)."""
    from wott_hub.examples import example_device
    from wott_hub.td.builder import build_tactile_td, static_property_values

    desc = example_device("flat", "pad")
    return build_tactile_td(desc), json.loads(encode(static_property_values(desc)))


def _fox(out):
    return decode(out.channel.schema_name, out.channel.schema, out.payload)


def _ros(out):
    from wott_hub.robotics.ros2_msgs import typestore

    ts = typestore()
    raw = ts.serialize_cdr(out.payload, out.channel.schema_name)
    return ts.deserialize_cdr(raw, out.channel.schema_name)


def test_ros_names_are_tokens_and_distinct():
    assert ros_token("barrel-1") == "barrel_1"
    assert ros_token("9lives") == "t_9lives"
    assert ros_token("a--b__c") == "a_b_c"
    assert ros_token("---") == "thing"
    assert ros_namespaces(["a-b", "a_b", "a.b"]) == {"a-b": "a_b", "a_b": "a_b_2", "a.b": "a_b_3"}


def test_the_sensor_frame_becomes_a_pose():
    assert frame_pose(None).rotation == (0.0, 0.0, 0.0, 1.0)
    # axes turned 90 degrees about z, origin 10 mm up: a quarter turn, translation in metres
    pose = frame_pose({"originLocation": {"x": 0, "y": 0, "z": 10}, "axisOrientation": {
        "xAxis": {"x": 0, "y": 1, "z": 0}, "yAxis": {"x": -1, "y": 0, "z": 0},
        "zAxis": {"x": 0, "y": 0, "z": 1}}})
    assert pose.translation == (0.0, 0.0, 0.01)
    np.testing.assert_allclose(pose.rotation, (0, 0, np.sqrt(0.5), np.sqrt(0.5)), atol=1e-12)
    half = frame_pose({"axisOrientation": {"xAxis": {"x": -1, "y": 0, "z": 0},
                                           "yAxis": {"x": 0, "y": -1, "z": 0}}})
    np.testing.assert_allclose(np.abs(half.rotation), (0, 0, 1, 0), atol=1e-12)
    for bad in ({"axisOrientation": {"xAxis": {"x": 1, "y": 0, "z": 0}, "yAxis": {"x": 2, "y": 0, "z": 0}}},
                {"originLocation": {"x": float("nan"), "y": 0, "z": 0}}):
        with pytest.raises(InvalidInput, match="sensorCoordinateFrame"):
            frame_pose(bad)


def test_the_throttle_draws_at_most_once_a_slot_and_never_loses_the_latest():
    th = Throttle(10.0)  # a slot every 100 ms (10 % slack)
    drawn: list[tuple[str, int]] = []

    def offer(name: str, t_ms: int) -> None:
        drawn.extend(th.offer(t_ms * 10**6, lambda at: [(name, at // 10**6)]))  # type: ignore[list-item]

    offer("a", 0)
    offer("b", 30)
    offer("c", 60)  # b replaced by c: only the latest waits
    assert drawn == [("a", 0)] and th.deadline == 100 * 10**6
    assert th.due(95 * 10**6) == [("c", 100)]  # within the slack: drawn, at the slot's time
    offer("d", 150)  # too early for the next slot (200)
    assert th.due(160 * 10**6) == []
    offer("e", 300)  # a packet in a new slot is drawn at once; the pending one it replaces is gone
    assert drawn[-1] == ("e", 300) and th.due(10**12) == []


def test_a_payload_the_mapping_cannot_read_stays_raw(pad):
    td, static = pad
    for profile in ("foxglove", "ros2"):
        fleet = FleetMapping(profile)
        m = fleet.add("pad", td, static)
        bad = Record("pad", 1, KIND_PROPERTY, "contactInformation", 5, '{"numOfContacts": "many"}')
        out = [o for o in fleet.record(bad) if "/skin" not in o.channel.topic]  # the mesh comes first
        assert m.unreadable == 1
        if profile == "foxglove":
            assert [o.payload for o in out] == [bad.data.encode()]
        else:  # its JSON as a String: nothing recorded is missing from a bag
            assert [(o.channel.topic, _ros(o).data) for o in out] == [
                ("/pad/properties/contactInformation", bad.data)]
        foreign = Record("pad", 2, KIND_EVENT, "somethingElse", 6, '{"x": 1}')
        out = fleet.record(foreign)
        if profile == "ros2":
            assert [(o.channel.topic, o.channel.schema_name, _ros(o).data) for o in out] == [
                ("/pad/events/somethingElse", "std_msgs/msg/String", '{"x": 1}')]


# --- issue 29: what the other engineer's records become --------------------------------------------

def _displacement(ids, disp, t_ns=1_700_000_000_123_456_789) -> Record:
    """A ``skinDisplacement`` record in the shape issue 29 gives (mm, sensor frame)."""
    value = {"timeStamp": t_ns, "numOfDisplacedNodes": len(ids), "arrayOfDisplacedNodes": [
        {"nodeID": i, "displacement": {"x": d[0], "y": d[1], "z": d[2]}}
        for i, d in zip(ids, disp, strict=True)]}
    return Record("pad", 7, KIND_EVENT, "skinDisplacement", t_ns + 1000, encode(value))


def test_the_displacement_field_in_both_encodings(pad):
    td, static = pad
    nodes = {n["nodeID"]: n["nodeLocation"] for n in static["skinNodes"]["arrayOfNodes"]}
    ids = [3, 10, 11]
    disp = [(0.1, -0.2, -1.5), (0.0, 0.0, -0.75), (0.25, 0.5, 0.0)]
    rec = _displacement([*ids, 10**6], [*disp, (1, 1, 1)])  # an id the mesh lacks: left out
    want_now = np.array([[nodes[i][k] for k in "xyz"] for i in ids]) / 1000 + np.array(disp) / 1000

    fox = FleetMapping("foxglove")
    fox.add("pad", td, static)
    out = [o for o in fox.record(rec) if o.channel.encoding == "protobuf"]
    cloud_out = next(o for o in out if o.channel.topic == "/pad/scene/displacement")
    cloud = _fox(cloud_out)
    assert cloud_out.channel.schema_name == "foxglove.PointCloud" and cloud.frame_id == "pad"
    assert cloud.timestamp.seconds * 10**9 + cloud.timestamp.nanos == 1_700_000_000_123_456_789
    data = np.frombuffer(cloud.data, dtype=[(f.name, "<f4" if f.name != "node_id" else "<u4")
                                            for f in cloud.fields])
    assert data["node_id"].tolist() == ids and cloud.point_stride == 28
    np.testing.assert_allclose(np.column_stack([data["x"], data["y"], data["z"]]), want_now, atol=1e-7)
    np.testing.assert_allclose(np.column_stack([data["dx"], data["dy"], data["dz"]]), np.array(disp) / 1000,
                               atol=1e-9)

    ros = FleetMapping("ros2")
    ros.add("pad", td, static)
    out = [o for o in ros.record(rec) if o.channel.topic == "/pad/skin/displacement"]
    msg = _ros(out[0])
    assert out[0].channel.schema_name == "sensor_msgs/msg/PointCloud2"
    assert [f.name for f in msg.fields] == ["x", "y", "z", "dx", "dy", "dz", "node_id"]
    rows = np.frombuffer(msg.data.tobytes(), dtype="<f4").reshape(-1, 7)
    assert rows[:, 6].view("<u4").tolist() == ids
    np.testing.assert_allclose(rows[:, :3], want_now, atol=1e-7)
    assert msg.header.stamp.sec == 1_700_000_000 and msg.header.stamp.nanosec == 123_456_789
    assert not [o for o in ros.record(rec) if "String" in o.channel.schema_name]  # mapped: no raw copy


PNG = b"\x89PNG\r\n\x1a\n" + bytes(range(32))
JPEG = b"\xff\xd8\xff\xe0" + bytes(range(32))


@pytest.mark.parametrize("data, form", [(PNG, "png"), (JPEG, "jpeg"),
                                        (np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3), "rgb8"),
                                        (np.arange(2 * 3 * 4, dtype=np.uint8).reshape(2, 3, 4), "rgba8"),
                                        (np.arange(6, dtype=np.uint8).reshape(2, 3), "mono8")])
def test_a_camera_image_in_both_encodings(pad, data, form):
    td, static = pad
    img = ImageFrame("left", 1_700_000_001_000_000_002, data)
    fox = FleetMapping("foxglove")
    (o,) = fox.add("pad", td, static).image(img)
    ros = FleetMapping("ros2")
    (r,) = ros.add("pad", td, static).image(img)
    msg, rmsg = _fox(o), _ros(r)
    assert o.t_ns == r.t_ns == img.t_ns
    if isinstance(data, bytes):
        assert (o.channel.topic, o.channel.schema_name) == ("/pad/camera/left/compressed",
                                                            "foxglove.CompressedImage")
        assert (msg.format, msg.data) == (form, data)
        assert (r.channel.topic, r.channel.schema_name) == ("/pad/camera/left/image_raw/compressed",
                                                            "sensor_msgs/msg/CompressedImage")
        assert (rmsg.format, rmsg.data.tobytes()) == (form, data)
    else:
        h, w = data.shape[:2]
        assert (o.channel.topic, o.channel.schema_name) == ("/pad/camera/left/raw", "foxglove.RawImage")
        assert (msg.width, msg.height, msg.encoding, msg.data) == (w, h, form, data.tobytes())
        assert (r.channel.topic, r.channel.schema_name) == ("/pad/camera/left/image_raw",
                                                            "sensor_msgs/msg/Image")
        assert (rmsg.width, rmsg.height, rmsg.encoding, rmsg.step) == (w, h, form, len(data.tobytes()) // h)
        assert rmsg.data.tobytes() == data.tobytes() and rmsg.header.frame_id == "pad"


def test_images_that_are_not_images_are_refused():
    for camera, data in (("left", b"GIF89a"), ("", PNG), ("a/b", PNG),
                         ("left", np.zeros((2, 2, 2), np.uint8)), ("left", np.zeros((2, 2), np.float32)),
                         ("left", np.zeros((0, 2), np.uint8))):
        with pytest.raises(InvalidInput, match="image"):
            ImageFrame(camera, 1, data)


def test_a_taxel_grid_as_tactile_state_and_a_float_image(pad):
    td, static = pad
    grid = TaxelGrid(5_000_000_007, np.arange(12, dtype=np.float64).reshape(3, 4) * 0.5)
    (o,) = FleetMapping("foxglove").add("pad", td, static).taxels(grid)
    (r,) = FleetMapping("ros2").add("pad", td, static).taxels(grid)
    img = _fox(o)
    assert (img.width, img.height, img.encoding, img.step) == (4, 3, "32FC1", 16)
    np.testing.assert_array_equal(np.frombuffer(img.data, "<f4").reshape(3, 4), grid.values)
    state = _ros(r)
    assert r.channel.schema_name == "tactile_msgs/msg/TactileState" and r.channel.topic == "/pad/taxels"
    assert [s.name for s in state.sensors] == ["pad"]
    np.testing.assert_array_equal(state.sensors[0].values, grid.values.ravel())
    with pytest.raises(InvalidInput, match="taxel grid"):
        TaxelGrid(1, np.array([[1.0, float("nan")]]))


def test_the_tactile_state_definition_is_tactile_toolboxs():
    """The bag embeds TactileState's definition: the fields of tactile_toolbox's message."""
    from wott_hub.robotics.ros2_msgs import typestore

    text, _ = typestore().generate_msgdef("tactile_msgs/msg/TactileState", ros_version=2)
    assert text.splitlines()[:2] == ["std_msgs/Header header", "sensor_msgs/ChannelFloat32[] sensors"]
    assert "MSG: sensor_msgs/ChannelFloat32\nstring name\nfloat32[] values" in text
