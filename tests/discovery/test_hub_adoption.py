"""The hub on mDNS, between processes on loopback: another process finds the hub's directory and
Things with their TXT records; a WoT device simulator in another process announces itself, the hub
adopts it as a ``wot-remote`` device, and a press on the device is a ``skinDeformedDetection`` event
of the re-exposed device, resumed across an outage, marked disconnected when the device leaves and
re-targeted (not duplicated) when it comes back on another address.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from typing import Any

import httpx
from httpx_sse import aconnect_sse

from wott_hub.config import HubConfig
from wott_hub.hub import Hub
from wott_hub.network import DiscoveryConfig
from wott_hub.td.validate import validate_td

FOREIGN = "urn:example:wot-skin-7"


class Collector:
    """The re-exposed device's skinDeformedDetection events, read over the hub's SSE form."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.packets: list[dict[str, Any]] = []
        self.open = asyncio.Event()
        self.task = asyncio.ensure_future(self._run())

    async def _run(self) -> None:
        async with httpx.AsyncClient(timeout=httpx.Timeout(5, read=None)) as client:
            async with aconnect_sse(client, "GET", self.url) as source:
                self.open.set()
                async for sse in source.aiter_sse():
                    self.packets.append(json.loads(sse.data))

    async def close(self) -> None:
        self.task.cancel()
        with contextlib.suppress(asyncio.CancelledError, Exception):
            await self.task


def same_packets(source: list[dict[str, Any]], reexposed: list[dict[str, Any]]) -> None:
    """Same times, nodes and intensities: the re-exposed device is exactly as precise as the packets."""
    by_time = {p["timeStamp"]: p for p in reexposed}
    for p in source:
        q = by_time.get(p["timeStamp"])
        assert q is not None, f"packet at {p['timeStamp']} not re-exposed"
        assert {n["deformedNodeID"]: n["deformedNodeIntensity"] for n in q["arrayOfDeformedNodes"]} == \
            {n["deformedNodeID"]: n["deformedNodeIntensity"] for n in p["arrayOfDeformedNodes"]}


def test_the_hub_announces_itself_and_adopts_a_wot_device_from_another_process(tmp_path, wait_for, run,
                                                                              device_sim, discover):
    async def scenario() -> None:
        cfg = HubConfig(name="hub-under-test", http_port=0, ws_port=0, database=str(tmp_path / "hub.db"),
                        discovery=DiscoveryConfig(mdns=True, browse=True))
        hub = Hub(cfg)
        await hub.start()
        http = httpx.AsyncClient(timeout=10)
        sim = None
        collector = None
        try:
            # another process browses (again if a busy machine made it miss one of ours in its 2 s
            # window) while the device simulator starts in a third one
            names = {f"hub-under-test {hub.hub_id}", f"hub on hub-under-test {hub.hub_id}"}
            browsing = asyncio.ensure_future(discover(names, 2))
            sim = await device_sim("127.0.0.1", "skin-7", FOREIGN).start()
            sim_url = sim.base
            rows = await browsing
            tdd = rows[f"hub-under-test {hub.hub_id}"]  # instance names carry the hub id
            assert tdd["type"] == "Directory" and tdd["td_type"] == "Directory"
            assert tdd["txt"] == {"td": "/.well-known/wot", "type": "Directory", "scheme": "http"}
            assert tdd["port"] == hub._server.http_port and tdd["addresses"] == ["127.0.0.1"]
            assert tdd["id"] == hub._network.directory.directory.own_id
            thing = rows[f"hub on hub-under-test {hub.hub_id}"]
            assert thing["txt"] == {"td": "/wot/hub", "type": "Thing", "scheme": "http"}
            assert thing["id"] == hub._identity.hub_thing_id

            # the simulator's announcement: fetched, claimed by wot-remote, exposed as a device
            await wait_for(lambda: "skin-7" in hub.devices and hub.devices["skin-7"].driver.connects > 0,
                           what="the WoT device adopted and streaming")
            assert hub._network.discovery.adopted == {FOREIGN: "skin-7"}
            dev = hub.devices["skin-7"]
            assert dev.family == "wot-remote" and dev.health_state() == ("ok", "")
            assert sorted(hub.devices) == ["skin-7"]  # nothing of the hub's own was adopted
            td = (await http.get(hub.td_url("skin-7"))).json()
            assert td["tac:family"] == "wot-remote" and td["title"] == "skin-7"
            assert validate_td(td) == []
            listed = (await http.get(f"{hub.http_url}/things")).json()
            assert hub._identity.device_id("skin-7") in {t["id"] for t in listed}
            mesh = (await http.get(f"{hub.td_url('skin-7')}/properties/skinNodes")).json()
            source_mesh = (await http.get(f"{sim_url}wot/pad-1/properties/skinNodes")).json()
            assert mesh == source_mesh

            # a press on the device is an event of the re-exposed device
            collector = Collector(f"{hub.td_url('skin-7')}/events/skinDeformedDetection")
            await asyncio.wait_for(collector.open.wait(), 10)
            pressed = [p["packet"] for p in (await http.post(f"{sim_url}press")).json()]
            assert len(pressed) > 5
            await wait_for(lambda: len(collector.packets) >= len(pressed), what="re-exposed packets")
            same_packets(pressed, collector.packets)

            # an outage: the stream drops, new connections are refused for a while, the device is
            # pressed meanwhile; the driver reconnects with Last-Event-ID and nothing is lost
            seen = len(collector.packets)
            await http.post(f"{sim_url}outage?seconds=0.8")
            pressed_offline = [p["packet"] for p in (await http.post(f"{sim_url}press")).json()]
            await wait_for(lambda: dev.driver.connects >= 2, what="reconnected after the outage")
            await wait_for(lambda: len(collector.packets) >= seen + len(pressed_offline),
                           what="packets sent during the outage")
            same_packets(pressed_offline, collector.packets[seen:])
            assert len(collector.packets) == seen + len(pressed_offline)  # none twice

            # the device leaves: the re-exposed device stays, disconnected
            await sim.stop()
            await wait_for(lambda: dev.health_state()[0] == "disconnected", what="marked disconnected")
            assert "skin-7" in hub.devices

            # ... and comes back on another address: the same device, re-targeted
            sim = await device_sim("127.0.0.2", "skin-7", FOREIGN).start()
            sim_url = sim.base
            await wait_for(lambda: dev.driver.td["base"].startswith("http://127.0.0.2:")
                           and dev.health_state()[0] == "ok", what="re-targeted to 127.0.0.2")
            assert sorted(hub.devices) == ["skin-7"] and hub.devices["skin-7"] is dev
            seen = len(collector.packets)
            pressed = [p["packet"] for p in (await http.post(f"{sim_url}press")).json()]
            await wait_for(lambda: len(collector.packets) >= seen + len(pressed), what="packets after return")
            same_packets(pressed, collector.packets[seen:])
        finally:
            if collector is not None:
                await collector.close()
            await http.aclose()
            if sim is not None:
                await sim.stop()
            await hub.stop()

    run(scenario(), 90)
