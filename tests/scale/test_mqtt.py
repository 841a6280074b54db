"""The MQTT event path through a real Mosquitto: every event and property change on the topics
the TDs' forms name (W3C WoT MQTT binding template), retained TDs, a broker restart survived and a
missing broker never holding the hub up."""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys

import jsonschema
import pytest

from wott_hub.config import HubConfig
from wott_hub.hub import Hub
from wott_hub.mqtt import MqttConfig
from wott_hub.servient import HUB_THING_ID
from wott_hub.td.validate import validate_td

EVENT = "skinDeformedDetection"
CONTACTS = "contactInformation"


def hub_config(tmp_path, press_scene, url: str, **mqtt) -> HubConfig:
    return HubConfig(name="cell", http_port=0, ws_port=None, database=str(tmp_path / "hub.db"),
                     devices=(press_scene("pad"),), mqtt=MqttConfig(url=url, **mqtt))


def mqtt_form(affordance: dict) -> dict:
    forms = [f for f in affordance["forms"] if f["href"].startswith("mqtt://")]
    assert len(forms) == 1, affordance["forms"]
    return forms[0]


def test_events_and_property_changes_on_the_topics_of_the_td_forms(tmp_path, press_scene, broker,
                                                                    mqtt_reader, run, wait_for):
    async def scenario() -> None:
        async with Hub(hub_config(tmp_path, press_scene, broker.url)) as hub:
            td = hub._server.things.get("pad").td
            assert {"mqv": "https://www.w3.org/2019/wot/mqtt#"} in td["@context"]
            assert validate_td(td) == []  # TD 1.1 and Tactile, MQTT forms included
            ev, prop = mqtt_form(td["events"][EVENT]), mqtt_form(td["properties"][CONTACTS])
            prefix = f"wott/{hub.hub_id}/pad"
            assert ev == {"href": f"{broker.url}/{prefix}/events/{EVENT}",
                          "mqv:filter": f"{prefix}/events/{EVENT}",
                          "op": ["subscribeevent", "unsubscribeevent"], "mqv:controlPacket": "subscribe",
                          "mqv:qos": "0", "contentType": "application/json"}
            assert prop["mqv:filter"] == f"{prefix}/properties/{CONTACTS}"
            assert prop["op"] == ["observeproperty", "unobserveproperty"]
            assert prop["mqv:retain"] is True and prop["mqv:qos"] == "0"  # per frame: event_qos
            health = mqtt_form(hub._server.things.get(HUB_THING_ID).td["properties"]["health"])
            assert health["mqv:retain"] is True and health["mqv:qos"] == "1"
            action = mqtt_form(td["events"]["actionDetection"])
            assert action["mqv:qos"] == "1" and action["mqv:filter"] == f"{prefix}/events/actionDetection"
            assert "mqv:filter" not in json.dumps(td["properties"]["skinMaterial"])  # not observable: no form

            # a WoT client subscribes to what the forms say, and nothing else
            async with mqtt_reader(broker.url, ev["mqv:filter"], prop["mqv:filter"]) as reader:
                await wait_for(lambda: len(reader.on(ev["mqv:filter"])) >= 20
                               and reader.on(prop["mqv:filter"]),
                               timeout=20, what=lambda: f"MQTT messages {sorted(reader.topics())}")
            # the same texts the hub serves over SSE and records (the ring holds the recent ones)
            served = {r.data for r in hub._plane.stream("pad").ring if r.name == EVENT}
            got = [p.decode() for t, p, _ in reader.messages if t == ev["mqv:filter"]]
            assert served & set(got)
            for g in got[:20]:  # each one valid against the event's data schema in the TD
                jsonschema.validate(json.loads(g), td["events"][EVENT]["data"])
            health = hub.health()["mqtt"]
            assert health["state"] == "ok" and health["published"] >= 20 and health["dropped"] == 0

    run(scenario())


def test_retained_tds_and_values_for_late_subscribers_and_cleared_on_a_clean_stop(
        tmp_path, press_scene, broker, mqtt_reader, run, wait_for):
    async def scenario() -> None:
        async with Hub(hub_config(tmp_path, press_scene, broker.url)) as hub:
            prefix = f"wott/{hub.hub_id}"
            await wait_for(lambda: hub._mqtt.published > 5 and not hub._mqtt.queue, timeout=20,
                           what="published")
            async with mqtt_reader(broker.url, f"{prefix}/+/td", f"{prefix}/+/properties/+") as late:
                await wait_for(lambda: {f"{prefix}/pad/td", f"{prefix}/hub/td"} <= late.topics(), timeout=10,
                               what=lambda: f"retained TDs {sorted(late.topics())}")
            tds = {t: json.loads(p) for t, p, retained in late.messages if t.endswith("/td") and retained}
            assert tds[f"{prefix}/pad/td"]["id"] == hub._server.things.get("pad").td["id"]
            assert tds[f"{prefix}/hub/td"]["id"] == f"urn:wott-hub:{hub.hub_id}:hub"
            assert any(t == f"{prefix}/pad/properties/{CONTACTS}" and r for t, _, r in late.messages)
        async with mqtt_reader(broker.url, f"{prefix}/#") as after:  # clean stop: nothing retained left
            await asyncio.sleep(0.5)
            assert [t for t, p, _ in after.messages if p] == []

    run(scenario())


def test_a_broker_restart_is_survived(tmp_path, press_scene, broker, mqtt_reader, run, wait_for):
    async def scenario() -> None:
        async with Hub(hub_config(tmp_path, press_scene, broker.url, reconnect_max_s=0.5)) as hub:
            topic = f"wott/{hub.hub_id}/pad/events/{EVENT}"
            await wait_for(lambda: hub._mqtt.connected, timeout=10, what="connected")
            await asyncio.to_thread(broker.restart)  # no persistence: retained TDs are gone with it
            await wait_for(lambda: hub._mqtt.connects >= 2 and hub._mqtt.connected, timeout=15,
                           what=lambda: f"reconnected: {hub.health()['mqtt']}")
            async with mqtt_reader(broker.url, topic, f"wott/{hub.hub_id}/pad/td") as reader:
                await wait_for(lambda: len(reader.on(topic)) >= 10 and reader.on(f"wott/{hub.hub_id}/pad/td"),
                               timeout=20, what=lambda: f"after the restart {sorted(reader.topics())}")
            assert hub.health()["mqtt"]["state"] == "ok"

    run(scenario())


def test_an_absent_broker_never_holds_the_hub_up(tmp_path, press_scene, broker_class, mqtt_reader, run,
                                                  wait_for, sse_events):
    async def scenario() -> None:
        later = broker_class(tmp_path)  # its port, nobody listening yet
        cfg = hub_config(tmp_path, press_scene, later.url, queue_max=50, reconnect_max_s=0.3)
        async with Hub(cfg) as hub:
            assert hub.state == "ok"
            url = f"{hub.http_url}/wot/pad/events/{EVENT}"
            events = await asyncio.to_thread(sse_events, url, 5)  # SSE streams as ever
            assert len(events) == 5
            await wait_for(lambda: hub._mqtt.dropped > 0, timeout=15, what="drops counted")
            health = hub.health()
            assert health["state"] == "degraded" and health["mqtt"]["state"] == "disconnected"
            assert health["mqtt"]["queued"] <= 50 and health["mqtt"]["error"]
            await asyncio.to_thread(later.start)
            try:
                topic = f"wott/{hub.hub_id}/pad/events/{EVENT}"
                async with mqtt_reader(later.url, topic) as reader:
                    await wait_for(lambda: len(reader.on(topic)) >= 5, timeout=20,
                                   what="events once it is up")
                assert hub.health()["mqtt"]["state"] == "ok"
            finally:
                await hub.stop()
                later.stop()

    run(scenario())


def test_bursts_of_every_size_and_qos_arrive_whole_and_in_order_per_topic(tmp_path, broker, mqtt_reader, run,
                                                                          wait_for):
    """The publisher writes QoS 0 messages joined (its own PUBLISH encoding) and QoS 1 ones through
    paho: sizes across each width of MQTT's remaining length and past one joined write."""
    sizes = [1, 117, 118, 16_373, 16_374, 70_000, 2_097_142, 2_097_143, 300]  # "burst/e0": 10 header bytes
    cfg = HubConfig(name="cell", http_port=0, ws_port=None, history=False, mqtt=MqttConfig(url=broker.url))

    async def scenario() -> None:
        async with Hub(cfg) as hub, mqtt_reader(broker.url, "burst/#") as reader:
            await wait_for(lambda: hub._mqtt.connected, timeout=10, what="connected")
            sent: dict[str, list[bytes]] = {}
            for burst in range(4):  # each burst put at once: one batch of the publisher
                for i in range(400):
                    size = sizes[i % len(sizes)] if burst == 0 else 200 + i
                    topic, qos = (f"burst/p{i % 2}", 1) if i % 5 == 0 else (f"burst/e{i % 3}", 0)
                    payload = f"{burst}:{i}:".encode().ljust(size, b"x")
                    sent.setdefault(topic, []).append(payload)
                    hub._mqtt.put((topic, payload, qos, False))
                total = sum(map(len, sent.values()))
                await wait_for(lambda n=total: len(reader.messages) >= n, timeout=30,
                               what=lambda n=total: f"{len(reader.messages)} of {n} messages")
            got: dict[str, list[bytes]] = {}
            for topic, payload, _ in reader.messages:
                got.setdefault(topic, []).append(payload)
            assert got == sent
            assert hub._mqtt.dropped == 0

    run(scenario(), timeout=120)


@pytest.mark.parametrize("immediate", [True, False])
def test_a_message_put_while_nothing_waits_is_written_at_once_or_batched_and_all_keep_their_order(
        tmp_path, broker, mqtt_reader, run, wait_for, immediate):
    """``[mqtt] immediate``: a QoS 0 message put while nothing waits is on the socket when ``put``
    returns; one larger than the socket takes leaves its rest to paho, and what follows waits
    behind it in the queue. Off: every message waits for the publisher's batch."""
    cfg = HubConfig(name="cell", http_port=0, ws_port=None, history=False,
                    mqtt=MqttConfig(url=broker.url, immediate=immediate))

    async def scenario() -> None:
        async with Hub(cfg) as hub, mqtt_reader(broker.url, "now/#") as reader:
            mq = hub._mqtt
            await wait_for(lambda: mq.connected and mq.idle, timeout=10,
                           what="the publisher idle")
            sent = [(f"now/{'ab'[i % 2]}", f"{i}:".encode().ljust(16_000_000 if i == 3 else 100, b"x"))
                    for i in range(300)]
            published = mq.published
            for i, (topic, payload) in enumerate(sent):
                mq.put((topic, payload, 0, False))
                if i == 0:  # nothing waited before it
                    assert (mq.published - published, len(mq.queue)) == ((1, 0) if immediate else (0, 1))
                if i == 4 and immediate:  # behind the rest of the 16 MB message, which paho holds
                    assert mq.queue
                if i % 10 == 0:
                    await asyncio.sleep(0)  # the publisher's turn: it sends what waits
            await wait_for(lambda: len(reader.messages) >= len(sent), timeout=60,
                           what=lambda: f"{len(reader.messages)} of {len(sent)} messages")
            for name in ("now/a", "now/b"):
                assert [p for t, p, _ in reader.messages if t == name] == [p for t, p in sent if t == name]

    run(scenario(), timeout=120)


def test_a_message_that_fails_to_be_written_at_once_stays_in_the_publisher(tmp_path, broker, mqtt_reader, run,
                                                                          wait_for):
    """``put`` runs inside the event plane's publish, on a device's pipeline: whatever writing at once
    raises (here a payload that is not text) is logged there, never raised; writing at once stops
    until the next connection and the next messages still arrive."""
    cfg = HubConfig(name="cell", http_port=0, ws_port=None, history=False, mqtt=MqttConfig(url=broker.url))

    async def scenario() -> None:
        async with Hub(cfg) as hub, mqtt_reader(broker.url, "now/#") as reader:
            mq = hub._mqtt
            await wait_for(lambda: mq.connected and mq.idle, timeout=10, what="the publisher idle")
            mq.put(("now/bad", 12345, 0, False))  # type: ignore[arg-type]  # not raised here
            await wait_for(lambda: mq.connected and mq.idle, timeout=10, what="the publisher idle again")
            mq.put(("now/ok", b"after", 0, False))
            await wait_for(lambda: any(t == "now/ok" for t, _, _ in reader.messages), timeout=10,
                           what="the next message")

    run(scenario(), timeout=60)


def test_no_mqtt_without_its_table_and_no_mqtt_library_loaded(tmp_path):
    code = """
import asyncio, json, sys
from wott_hub.config import HubConfig
from wott_hub.hub import Hub
cfg = HubConfig.from_dict({"hub": {"id": "cell-1", "http_port": 0, "ws_port": False, "history": False}})
async def main():
    async with Hub(cfg) as hub:
        td = json.dumps(hub._server.things.get("hub").td)
        print(json.dumps({"mqtt": hub._mqtt is None, "forms": "mqtt://" in td or "mqv" in td,
                          "loaded": sorted(m for m in sys.modules if m.startswith(("aiomqtt", "paho")))}))
asyncio.run(main())
"""
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                         cwd=tmp_path)
    assert res.returncode == 0, res.stderr[-2000:]
    assert json.loads(res.stdout.strip().splitlines()[-1]) == {"mqtt": True, "forms": False, "loaded": []}
