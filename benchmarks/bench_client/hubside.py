"""The hub side: a hub serving ``n`` Tactile Things whose records the benchmark publishes itself."""

from __future__ import annotations

import asyncio
import json
import time
from typing import Any

__all__ = ["BenchHub", "packet_maker"]

EVENT = "skinDeformedDetection"
NODES = 20  # deformed nodes per packet: a fingertip on a 16x16 pad


def packet_maker(n_nodes: int = 256):
    """stamp -> encoded packet (``NODES`` nodes spread over the mesh), the stamp spliced into a template."""
    step = max(1, n_nodes // NODES)
    body = json.dumps({"timeStamp": 0, "numOfDeformedNodes": NODES, "arrayOfDeformedNodes": [
        {"deformedNodeID": i * step, "deformedNodeIntensity": round(0.1 + i / 97, 3)} for i in range(NODES)]},
        separators=(",", ":"))
    head, tail = '{"timeStamp":', body.split(",", 1)[1]
    return lambda stamp: f"{head}{stamp},{tail}"


class BenchHub:
    def __init__(self, n_things: int) -> None:
        self.n = n_things
        self.hub: Any = None
        self.ids = [f"dev-{i}" for i in range(n_things)]

    async def start(self) -> BenchHub:
        from wott_hub.config import HubConfig
        from wott_hub.examples import example_device
        from wott_hub.hub import Hub
        from wott_hub.td.builder import build_tactile_td, static_property_values

        self.hub = Hub(HubConfig(http_port=0, ws_port=0, history=False, max_pending=1_000_000))
        await self.hub.start()
        desc = example_device("flat")
        self.n_nodes = len(desc.mesh.nodes)
        for thing in self.ids:
            await self.hub.expose_thing(thing, build_tactile_td(desc),
                                        static_values=static_property_values(desc))
        return self

    @property
    def td_urls(self) -> list[str]:
        return [self.hub.td_url(t) for t in self.ids]

    def subscribed(self) -> bool:
        from wott_hub.events.record import KIND_EVENT

        return all(self.hub._plane.streams[t].interested(KIND_EVENT, EVENT) for t in self.ids)

    async def publish_at(self, rate: float, duration: float) -> dict[str, list[int]]:
        """``rate`` records/s in all, round-robin over the Things, in 5 ms bursts, each stamped with the
        wall clock at publication; returns each Thing's published seqs."""
        from wott_hub.events.record import KIND_EVENT

        plane, make = self.hub._plane, packet_maker(self.n_nodes)
        seqs: dict[str, list[int]] = {t: [] for t in self.ids}
        n, t0 = 0, time.monotonic()
        while (elapsed := time.monotonic() - t0) < duration:
            due = int(rate * elapsed) + 1
            while n < due:
                thing = self.ids[n % self.n]
                stamp = time.time_ns()
                seqs[thing].append(plane.publish(thing, KIND_EVENT, EVENT, stamp, make(stamp)).seq)
                n += 1
            await asyncio.sleep(0.005)
        return seqs

    async def stop(self) -> None:
        await self.hub.stop()
