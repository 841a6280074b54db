"""``skinDisplacement`` through a real Mosquitto (issue 29): its JSON on the event's topic and its binary
form on a topic of its own, both named by the TD's forms, the norms equal to the same frame's intensities."""

from __future__ import annotations

import json
import struct

import numpy as np

from wott_hub.config import HubConfig
from wott_hub.hub import Hub
from wott_hub.mqtt import MqttConfig

NORM_BOUND_MM = (3**0.5 / 2 + 0.5) / 1000 + 1e-6


def test_the_vectors_and_their_binary_form_on_the_topics_of_the_td_forms(tmp_path, press_scene, broker,
                                                                          mqtt_reader, run, wait_for):
    async def scenario() -> None:
        cfg = HubConfig(name="cell", http_port=0, ws_port=None, database=str(tmp_path / "hub.db"),
                        devices=(press_scene("pad"),), mqtt=MqttConfig(url=broker.url))
        async with Hub(cfg) as hub:
            td = hub._server.things.get("pad").td
            forms = [f for f in td["events"]["skinDisplacement"]["forms"] if f["href"].startswith("mqtt://")]
            by_type = {f["contentType"]: f["mqv:filter"] for f in forms}
            json_topic = by_type["application/json"]
            binary_topic = by_type["application/vnd.wott.skin-displacement"]
            assert json_topic.endswith("/pad/events/skinDisplacement")
            assert binary_topic.endswith("/pad/binary/events/skinDisplacement")  # outside events/#
            intensity_topic = json_topic.replace("skinDisplacement", "skinDeformedDetection")
            async with mqtt_reader(broker.url, json_topic, binary_topic, intensity_topic) as reader:
                await wait_for(lambda: len(reader.on(json_topic)) >= 20 and sum(
                    t == binary_topic for t, _, _ in reader.messages) >= 20, timeout=30,
                    what=lambda: f"MQTT messages {sorted(reader.topics())}")
        intensities = {p["timeStamp"]: [n["deformedNodeIntensity"] for n in p["arrayOfDeformedNodes"]]
                       for p in reader.on(intensity_topic)}
        matched = 0
        for p in reader.on(json_topic):
            vec = np.array([[n["displacement"][a] for a in "xyz"] for n in p["arrayOfDisplacedNodes"]])
            if p["timeStamp"] in intensities and len(vec):
                gap = np.abs(np.linalg.norm(vec, axis=1) - intensities[p["timeStamp"]])
                assert gap.max() <= NORM_BOUND_MM
                matched += 1
        assert matched >= 10
        texts = {p["timeStamp"]: p for p in reader.on(json_topic)}
        for _, payload, _ in [m for m in reader.messages if m[0] == binary_topic]:
            magic, n, seq, ts = struct.unpack_from("<4sIQq", payload)
            assert magic == b"WTD1" and len(payload) == 24 + 16 * n and seq > 0
            if ts in texts:  # the same packet as the JSON one
                ids = np.frombuffer(payload, "<u4", n, 24).tolist()
                vec = np.frombuffer(payload, "<f4", 3 * n, 24 + 4 * n).reshape(n, 3)
                nodes = texts[ts]["arrayOfDisplacedNodes"]
                assert ids == [d["nodeID"] for d in nodes]
                want = np.array([[d["displacement"][a] for a in "xyz"] for d in nodes]).reshape(-1, 3)
                np.testing.assert_allclose(vec, want, atol=1e-6)
        assert json.loads(json.dumps(texts))  # plain JSON all along

    run(scenario(), 90)
