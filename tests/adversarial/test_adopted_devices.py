"""Issue 33 item 5 and issue 32 item 6, devices announced on mDNS (no credentials needed), against a
real hub browsing 127.0.0.1: a Tactile Thing with a 360,000-node mesh (refused at the cap, nothing
built on the event loop: a healthy device's SSE reader never waits), one within the cap (adopted,
its mesh built off the loop), and a remote hub whose Things all refuse us (401): one warning for it,
the rest at debug. The announced devices are real HTTP servers announced by a real zeroconf."""

from __future__ import annotations

import asyncio
import json
import logging
import threading
import time

import pytest
from tornado.httpserver import HTTPServer
from tornado.netutil import bind_sockets
from tornado.web import Application, RequestHandler

from wott_hub.config import HubConfig
from wott_hub.network import DiscoveryConfig

from . import surroundings as S

EVENT = "skinDeformedDetection"
GAP_S = 2.5


def grid_mesh(rows: int, cols: int) -> tuple[bytes, bytes]:
    """``skinNodes`` and ``skinCells`` values of a flat rows x cols grid of quads (what a device sends)."""
    nodes = [{"nodeID": r * cols + c, "nodeLocation": {"x": c * 1.5, "y": r * 1.5, "z": 0.0}}
             for r in range(rows) for c in range(cols)]
    cells = [{"cellID": i, "connectedNodes": [r * cols + c, r * cols + c + 1, (r + 1) * cols + c + 1,
                                              (r + 1) * cols + c]}
             for i, (r, c) in enumerate((r, c) for r in range(rows - 1) for c in range(cols - 1))]
    return (json.dumps({"numOfNodes": len(nodes), "arrayOfNodes": nodes}).encode(),
            json.dumps({"numOfCells": len(cells), "arrayOfCells": cells}).encode())


class _Body(RequestHandler):
    def initialize(self, bodies: dict[str, bytes], status: int = 200) -> None:
        self.bodies = bodies
        self.status = status

    def get(self, name: str = "td") -> None:
        if self.status != 200:
            self.set_status(self.status)
            self.finish(b'{"title": "Unauthorized"}')
            return
        if name not in self.bodies:
            self.set_status(404)
            self.finish()
            return
        self.set_header("Content-Type", "application/json")
        self.finish(self.bodies[name])


class _Events(RequestHandler):
    async def get(self) -> None:
        self.set_header("Content-Type", "text/event-stream")
        self.write(": quiet\n\n")
        await self.flush()
        await asyncio.Event().wait()  # a device that never presses: open until the test ends


class Announced:
    """HTTP servers and their mDNS announcements (127.0.0.1), in a thread with its own event loop."""

    def __init__(self) -> None:
        self.loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self._thread.start()
        self._servers: list[HTTPServer] = []
        self.aiozc = None
        self.announcer = None

    def call(self, coro, timeout: float = 60):
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(timeout)

    async def _serve(self, routes: list) -> int:
        sockets = bind_sockets(0, "127.0.0.1")
        server = HTTPServer(Application(routes))
        server.add_sockets(sockets)
        self._servers.append(server)
        if self.announcer is None:
            from zeroconf.asyncio import AsyncZeroconf

            from wott_hub.discovery import Announcer

            self.aiozc = AsyncZeroconf(interfaces=["127.0.0.1"])
            self.announcer = Announcer(self.aiozc, addresses=["127.0.0.1"])
        return int(sockets[0].getsockname()[1])

    def tactile_device(self, name: str, nodes: bytes, cells: bytes) -> None:
        """A Tactile WoT device serving this mesh, announced as ``_wot._tcp``."""
        from wott_hub.examples import example_device
        from wott_hub.td.builder import build_tactile_td, static_property_values
        from wott_hub.td.forms import PREFIX

        async def start() -> None:
            desc = example_device("flat")
            values = {k: json.dumps(v).encode() for k, v in static_property_values(desc).items()}
            values.update(skinNodes=nodes, skinCells=cells)
            thing = f"{PREFIX}/{desc.id}"
            holder: dict[str, bytes] = {}
            port = await self._serve([("/td", _Body, {"bodies": holder}),
                                      (rf"{thing}/properties/([A-Za-z]+)", _Body, {"bodies": values}),
                                      (rf"{thing}/events/{EVENT}", _Events)])
            td = build_tactile_td(desc, base=f"http://127.0.0.1:{port}/")
            td.update(id=f"urn:example:{name}", title=name)
            holder["td"] = json.dumps(td).encode()
            await self.announcer.announce_thing(name, port, "/td")

        self.call(start())

    def refusing_hub(self, n: int) -> str:
        """``n`` Things announced by one server that answers 401 to everything; its origin."""
        async def start() -> int:
            port = await self._serve([(r"/wot/(.*)", _Body, {"bodies": {}, "status": 401})])
            for i in range(n):
                await self.announcer.announce_thing(f"locked-{i}", port, f"/wot/thing-{i}")
            return port

        return f"http://127.0.0.1:{self.call(start())}"

    def close(self) -> None:
        async def stop() -> None:
            if self.announcer is not None:
                await self.announcer.close()
                await self.aiozc.async_close()
            for server in self._servers:
                server.stop()

        try:
            self.call(stop())
        finally:
            self.loop.call_soon_threadsafe(self.loop.stop)
            self._thread.join(10)


@pytest.fixture
def browsing_hub(hub_thread, press_scene):
    ht = hub_thread(HubConfig(http_port=0, ws_port=None, history=False, devices=(press_scene("pad"),),
                              discovery=DiscoveryConfig(mdns=False, browse=True,
                                                        interfaces=("127.0.0.1",)))).start()
    yield ht
    ht.stop()


def discovery_of(ht) -> dict:
    return ht.call(lambda: ht.hub.describe()["discovery"])


def test_a_huge_tactile_device_on_mdns_is_refused_at_the_cap_without_stalling_the_hub(browsing_hub,
                                                                                     eventually):
    nodes, cells = grid_mesh(600, 600)  # 360,000 nodes: ~40 MB of skinNodes
    meter = S.GapMeter(f"{browsing_hub.url}/wot/pad/events/{EVENT}").start()
    rss0 = S.rss_mb()
    announced = Announced()
    try:
        t0 = time.monotonic()
        announced.tactile_device("huge-skin", nodes, cells)
        failed = eventually(lambda: discovery_of(browsing_hub)["failed"].get("urn:example:huge-skin"),
                            timeout=60, what="the huge device refused")
        gap = meter.longest_gap(t0)
        grown = S.rss_mb() - rss0
    finally:
        meter.stop()
        announced.close()
    assert "max_nodes" in failed and "not adopted" in failed, failed
    assert "huge-skin" not in browsing_hub.hub.devices
    assert gap < GAP_S, f"the healthy device's stream stalled {gap:.1f} s while the huge device was read"
    assert grown < 300, f"the hub grew by {grown:.0f} MB reading it"


def test_a_large_mesh_within_the_cap_is_adopted_and_built_off_the_loop(browsing_hub, eventually):
    from wott_hub.drivers.remote import MAX_NODES

    nodes, cells = grid_mesh(100, 150)  # 15,000 nodes, under MAX_NODES
    assert 15_000 < MAX_NODES
    meter = S.GapMeter(f"{browsing_hub.url}/wot/pad/events/{EVENT}").start()
    announced = Announced()
    try:
        t0 = time.monotonic()
        announced.tactile_device("big-skin", nodes, cells)
        device_id = eventually(lambda: discovery_of(browsing_hub)["adopted"].get("urn:example:big-skin"),
                               timeout=90, what=lambda: f"adopted: {discovery_of(browsing_hub)}")
        gap = meter.longest_gap(t0)
    finally:
        meter.stop()
        announced.close()
    assert browsing_hub.hub.devices[device_id].processor.mesh.n_nodes == 15_000
    assert gap < GAP_S, f"the healthy device's stream stalled {gap:.1f} s adopting a 15,000-node mesh"


def test_a_remote_hub_whose_things_refuse_us_is_one_warning(browsing_hub, eventually, caplog):
    caplog.set_level(logging.DEBUG, logger="wott_hub.discovery")
    announced = Announced()
    try:
        origin = announced.refusing_hub(6)  # each announcement is probed for ~1 s: 6 make the point
        explorer = browsing_hub.hub._network.discovery.explorer
        eventually(lambda: explorer.unreadable.get(origin, 0) >= 6, timeout=60,
                   what=lambda: f"6 refusals from {origin}: {explorer.unreadable}")
    finally:
        announced.close()
    about = [r for r in caplog.records if r.name == "wott_hub.discovery" and origin in r.getMessage()
             or "locked-" in r.getMessage()]
    warnings = [r for r in about if r.levelno >= logging.WARNING]
    assert len(warnings) == 1, [r.getMessage() for r in warnings]
    assert origin in warnings[0].getMessage() and "401" in warnings[0].getMessage()
    assert sum(1 for r in about if r.levelno == logging.DEBUG) >= 5  # the details, at debug
