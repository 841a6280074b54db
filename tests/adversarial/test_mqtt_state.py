"""Issue 33 item 12, MQTT state never stale, against a real Mosquitto on 127.0.0.1 and the real
``wott-hub run``: the hub's retained ``health`` says ``ok`` once it is up (not ``starting``), a clean
stop leaves nothing retained, a killed hub is marked offline by its last will, and a broker that
stops reading (SIGSTOP) or never answers a connection shows in health while every other client of the
hub carries on (an SSE reader's longest gap)."""

from __future__ import annotations

import json
import signal
import socket
import time
from pathlib import Path

import httpx

from wott_hub.config import HubConfig

from . import surroundings as S

EVENT = "skinDeformedDetection"
GAP_S = 2.5


def hub_process(folder: Path, broker) -> object:
    cfg = S.write_config(folder, f"""
[hub]
http_port = 0
ws_port = 0
database = "hub.db"

[discovery]
mdns = false
browse = false

[mqtt]
url = "{broker.url}"
reconnect_max_s = 0.5

{S.press_table("pad")}
""")
    return S.HubProcess(["-c", str(cfg)], folder)


def health_topic(hub_id: str) -> str:
    return f"wott/{hub_id}/hub/properties/health"


def retained_health(broker, hub_id: str) -> dict:
    """The hub's retained ``health`` a new subscriber gets ({} when there is none)."""
    return S.retained_json(broker.url, health_topic(hub_id)) or {}


def test_the_retained_health_says_ok_once_up_and_a_clean_stop_leaves_nothing(tmp_path, eventually):
    broker = S.Broker(tmp_path).start()
    hub = hub_process(tmp_path, broker)
    try:
        hub_id = hub.info["hub_id"]
        health = eventually(lambda: (h := retained_health(broker, hub_id)).get("state") == "ok" and h,
                            timeout=30, what=lambda: f"retained health: {retained_health(broker, hub_id)}")
        assert health["devices"]["pad"]["state"] == "ok"
        assert f"wott/{hub_id}/pad/td" in S.retained(broker.url, f"wott/{hub_id}/#")
        took = hub.stop()
        left = S.retained(broker.url, f"wott/{hub_id}/#")
    finally:
        if hub.proc.poll() is None:
            hub.proc.kill()
        broker.stop()
    assert left == {}, f"retained after a clean stop: {sorted(left)}"
    assert took < 20, f"the stop took {took:.1f} s"


def test_a_killed_hub_is_marked_offline_by_its_last_will(tmp_path, eventually):
    broker = S.Broker(tmp_path).start()
    hub = hub_process(tmp_path, broker)
    try:
        hub_id = hub.info["hub_id"]
        eventually(lambda: retained_health(broker, hub_id).get("state") == "ok", timeout=30,
                   what="the retained health says ok")
        hub.proc.send_signal(signal.SIGKILL)
        hub.proc.wait(10)
        health = eventually(lambda: (h := retained_health(broker, hub_id)).get("state") == "disconnected"
                            and h, timeout=15,
                            what=lambda: f"retained health: {retained_health(broker, hub_id)}")
    finally:
        if hub.proc.poll() is None:
            hub.proc.kill()
        broker.stop()
    assert "last will" in health["reason"] and "offline" in health["reason"], health


def test_a_broker_that_stops_reading_shows_in_health_and_costs_no_other_client(tmp_path, hub_thread,
                                                                               press_scene, eventually):
    from wott_hub.mqtt import MqttConfig

    broker = S.Broker(tmp_path).start()
    ht = hub_thread(HubConfig(http_port=0, ws_port=None, history=False, devices=(press_scene("pad"),),
                              mqtt=MqttConfig(url=broker.url, reconnect_max_s=0.5))).start()
    meter = S.GapMeter(f"{ht.url}/wot/pad/events/{EVENT}").start()

    def health() -> dict:
        return httpx.get(f"{ht.url}/wot/hub/properties/health", timeout=10).json()

    try:
        eventually(lambda: health()["mqtt"]["published"] > 20, timeout=30, what="publishing")
        t0 = time.monotonic()
        broker.pause()
        seen = eventually(lambda: (h := health())["mqtt"]["state"] != "ok" and h, timeout=40,
                          what=lambda: f"health while the broker reads nothing: {health()['mqtt']}")
        gap = meter.longest_gap(t0)
        broker.resume()
        eventually(lambda: health()["mqtt"]["state"] == "ok", timeout=60, what="ok again")
    finally:
        meter.stop()
        broker.stop()
        ht.stop()
    assert seen["state"] == "degraded", seen["state"]
    assert seen["mqtt"]["state"] in ("stalled", "disconnected") and seen["mqtt"]["error"], seen["mqtt"]
    assert gap < GAP_S, f"the device's SSE stream stalled {gap:.1f} s while the broker read nothing"


def test_a_broker_that_never_answers_a_connection_is_named_in_health(tmp_path, hub_thread, press_scene,
                                                                     eventually):
    from wott_hub.mqtt import MqttConfig

    with socket.socket() as silent:  # accepts connections (the kernel does) and never reads them
        silent.bind(("127.0.0.1", 0))
        silent.listen(16)
        port = silent.getsockname()[1]
        mqtt_cfg = MqttConfig(url=f"mqtt://127.0.0.1:{port}", reconnect_max_s=0.5)
        ht = hub_thread(HubConfig(http_port=0, ws_port=None, history=False, devices=(press_scene("pad"),),
                                  mqtt=mqtt_cfg)).start()
        try:
            mqtt = eventually(
                lambda: (m := httpx.get(f"{ht.url}/wot/hub/properties/health", timeout=10).json()["mqtt"])[
                    "error"] and m, timeout=40, what="a named connection failure (CONNECT_TIMEOUT_S: 10 s)")
            stop_t0 = time.monotonic()
        finally:
            ht.stop()
        took = time.monotonic() - stop_t0
    assert mqtt["state"] == "disconnected" and "CONNACK" in mqtt["error"], json.dumps(mqtt)
    assert took < 15, f"stopping with the silent broker took {took:.1f} s"
