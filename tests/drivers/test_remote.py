"""The built-in ``wot-remote`` family: which TDs it claims, and its driver consuming a real hub's
device over HTTP + SSE (a second hub, configured with the device's TD URL, re-exposes it)."""

from __future__ import annotations

import asyncio
import copy
import json
from typing import Any

import httpx
import numpy as np
from httpx_sse import aconnect_sse

from wott_hub.config import HubConfig
from wott_hub.drivers.base import Health
from wott_hub.drivers.remote import RemoteWoTDriver, re_exposed_epsilon
from wott_hub.examples import example_device
from wott_hub.hub import Hub
from wott_hub.plugins import DeviceConfig, Registry
from wott_hub.servient import FormLayout
from wott_hub.td.builder import build_tactile_td


def hub_device_td() -> dict[str, Any]:
    layout = FormLayout("http://10.0.0.5:8080", "ws://10.0.0.5:8081")
    td = build_tactile_td(example_device("flat"), base="http://10.0.0.5:8080/", forms=layout.factory("pad"))
    td["title"] = "Left Palm"
    return td


def test_claims_tactile_tds_with_usable_forms_only():
    registry = Registry(only=[])
    td = hub_device_td()
    cfg = registry.claim(td)
    assert cfg == DeviceConfig("left-palm", "wot-remote", {"td": td})
    # relative hrefs are resolved against base (a device's own TD, like the simulator's)
    relative = build_tactile_td(example_device("flat"), base="http://10.0.0.7/")
    assert registry.claim(relative).settings["td"] is not None

    copy_of_a_copy = {**td, "tac:family": "wot-remote"}
    assert registry.claim(copy_of_a_copy) is None  # a re-exposure: the original is adopted instead
    no_sse = copy.deepcopy(td)
    no_sse["events"]["skinDeformedDetection"]["forms"] = [
        f for f in no_sse["events"]["skinDeformedDetection"]["forms"] if f.get("subprotocol") != "sse"]
    assert registry.claim(no_sse) is None  # only a WebSocket form left: nothing this driver speaks
    no_cells = copy.deepcopy(td)
    del no_cells["properties"]["skinCells"]
    assert registry.claim(no_cells) is None
    lamp = {"@context": "https://www.w3.org/2022/wot/td/v1.1", "id": "urn:ex:lamp", "title": "lamp",
            "securityDefinitions": {"n": {"scheme": "nosec"}}, "security": "n"}
    assert registry.claim(lamp) is None


def test_epsilon_keeps_every_node_a_packet_can_carry():
    assert re_exposed_epsilon({"tac:epsilon": 0.1}) < 0.1 - 0.0005  # 0.1004 is sent rounded to 0.100
    assert re_exposed_epsilon({"tac:epsilon": 0.001}) == 0.0005
    assert re_exposed_epsilon({}) == 0.1 and re_exposed_epsilon({"tac:epsilon": 0.1}, 0.3) == 0.3


def test_a_hub_re_exposes_another_hubs_device_from_its_td_url(press_scene, wait_for, run):
    mesh = example_device("flat").mesh
    source_device = press_scene("pad", "flat", start_s=0.2)

    async def collect(url: str, out: list[dict], opened: asyncio.Event) -> None:
        async with httpx.AsyncClient(timeout=httpx.Timeout(5, read=None)) as c, \
                aconnect_sse(c, "GET", url) as source:
            opened.set()
            async for sse in source.aiter_sse():
                out.append(json.loads(sse.data))

    async def scenario() -> None:
        a = Hub(HubConfig(name="a", http_port=0, ws_port=0, history=False, devices=(source_device,)))
        await a.start()
        b = Hub(HubConfig(name="b", http_port=0, ws_port=0, history=False, devices=(
            DeviceConfig("palm", "wot-remote", {"url": a.td_url("pad"), "title": "Palm via b"}),
            DeviceConfig("gone", "wot-remote", {"url": "http://127.0.0.1:9/wot/nothing", "timeout_s": 1}),
        )))
        await b.start()
        tasks = []
        try:
            assert set(b.devices) == {"palm"}
            assert b.describe()["failed"]["gone"].startswith("cannot read the device at http://127.0.0.1:9/")
            driver: RemoteWoTDriver = b.devices["palm"].driver
            desc = driver.description
            np.testing.assert_allclose(desc.mesh.nodes, mesh.nodes, atol=1e-4)  # the TD rounds to 0.1 µm
            np.testing.assert_array_equal(desc.mesh.cells, mesh.cells)
            assert (desc.title, desc.family, desc.material.shore_hardness) == ("Palm via b", "wot-remote",
                                                                              "Shore 00-50")
            assert desc.epsilon_mm < example_device("flat").epsilon_mm
            assert b._server.things.get("palm").td["title"] == "Palm via b"

            # a packet -> each intensity along the inward normal; unknown nodes are dropped, reported
            packet = {"timeStamp": 7, "numOfDeformedNodes": 2, "arrayOfDeformedNodes": [
                {"deformedNodeID": 10, "deformedNodeIntensity": 0.5},
                {"deformedNodeID": 99999, "deformedNodeIntensity": 1.0}]}
            frame = driver._packet_frame(json.dumps(packet))
            np.testing.assert_allclose(frame.displacement[10], -0.5 * desc.mesh.normals[10])
            assert np.count_nonzero(np.abs(frame.displacement).sum(axis=1)) == 1
            assert driver.health().state == "degraded" and driver.bad_packets == 1
            assert driver._packet_frame("not json") is None and driver.bad_packets == 2
            driver.set_health(Health.ok)

            source, copy_, opened = [], [], [asyncio.Event(), asyncio.Event()]
            tasks = [asyncio.ensure_future(collect(f"{a.td_url('pad')}/events/skinDeformedDetection", source,
                                                   opened[0])),
                     asyncio.ensure_future(collect(f"{b.td_url('palm')}/events/skinDeformedDetection", copy_,
                                                   opened[1]))]
            await asyncio.wait_for(asyncio.gather(*(o.wait() for o in opened)), 10)
            await wait_for(lambda: len(copy_) >= 12 and source, timeout=10,
                           what=lambda: f"12 re-exposed packets and a source one (source {len(source)}, "
                                        f"re-exposed {len(copy_)})")
            by_time = {p["timeStamp"]: p for p in source}
            matched = [p for p in copy_ if p["timeStamp"] in by_time]
            assert len(matched) >= 10
            for p in matched:
                assert p == by_time[p["timeStamp"]]  # the same packet, byte for byte in content
            assert b.devices["palm"].health_state() == ("ok", "")
        finally:
            for t in tasks:
                t.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            await b.stop()
            await a.stop()

    run(scenario(), 60)
