"""The hub side: a hub with a Thing whose ``skinDisplacement`` records the benchmark publishes itself,
and a camera device whose 640 x 480 image changes at 60 frames/s (nothing else: the cost measured is
the hub's serving and the client's fetching, not a simulator's rendering)."""

from __future__ import annotations

import asyncio
import time
from typing import Any

import numpy as np

__all__ = ["FieldsHub"]

HEIGHT, WIDTH = 480, 640


def camera_driver_class():
    from wott_hub.plugin_api import Driver, RawSample, RawSignal, ServesRawSignals, TactileFrame

    class BenchCamera(Driver, ServesRawSignals):
        """A camera that shows a moving gradient: a new 640 x 480 grey image every 1/60 s."""

        def __init__(self, desc, fps: float = 60.0) -> None:
            super().__init__(desc)
            self.fps = fps
            self.raw_signals = (RawSignal("camera", "image", (HEIGHT, WIDTH), rate_hz=fps),)
            self._base = (np.add.outer(np.arange(HEIGHT), np.arange(WIDTH)) % 256).astype(np.uint8)
            self._last: RawSample | None = None
            self._closed = False

        async def frames(self):
            rest = np.zeros((self.description.mesh.n_nodes, 3))
            k = 0
            while not self._closed:
                t = time.time_ns()
                self._last = RawSample(t, np.roll(self._base, k, axis=1))
                yield TactileFrame(t, rest)
                k += 1
                await asyncio.sleep(1 / self.fps)

        def raw_sample(self, name: str) -> RawSample | None:
            return self._last if name == "camera" else None

        async def close(self) -> None:
            self._closed = True

    return BenchCamera


class FieldsHub:
    def __init__(self) -> None:
        self.hub: Any = None

    async def start(self) -> FieldsHub:
        from dataclasses import replace

        from wott_hub.config import HubConfig
        from wott_hub.examples import example_device
        from wott_hub.hub import Hub
        from wott_hub.td.builder import build_tactile_td, static_property_values

        self.hub = Hub(HubConfig(http_port=0, ws_port=0, history=False, max_pending=1_000_000))
        await self.hub.start()
        desc = example_device("flat")
        await self.hub.expose_thing("fields", build_tactile_td(desc),
                                    static_values=static_property_values(desc))
        await self.hub.add_driver(camera_driver_class()(replace(desc, id="camera", title="camera")))
        return self

    def url(self, thing: str) -> str:
        return self.hub.td_url(thing)

    async def publish(self, records: list, rate: float) -> float:
        """Put ``records`` (FieldRecords, seq 0) on the plane at ``rate``/s in 5 ms bursts; seconds taken."""
        plane = self.hub._plane
        n, t0 = 0, time.monotonic()
        while n < len(records):
            due = min(len(records), int(rate * (time.monotonic() - t0)) + 1)
            while n < due:
                rec = records[n]
                rec.thing, rec.seq = "fields", 0
                plane.put(rec)
                n += 1
            await asyncio.sleep(0.005)
        return time.monotonic() - t0

    async def stop(self) -> None:
        await self.hub.stop()
