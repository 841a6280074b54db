"""The real Mini presses through a real hub (a recording as ``source``): the TD declares contactRadii,
contactInformation is null until the rest reference, then every press is one contact and the background
none, in history as the clients saw it."""

from __future__ import annotations

import asyncio
import json
import threading
import time

import httpx
from wott_driver_gel.settings import open_gel

from wott_hub.config import HubConfig
from wott_hub.events.record import KIND_PROPERTY
from wott_hub.td.validate import validate_td


class _Hub:
    """A real hub on 127.0.0.1 (free ports) in its own thread and event loop."""

    def __init__(self, config: HubConfig) -> None:
        from wott_hub.hub import Hub

        self.hub = Hub(config)
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.started = threading.Event()

    def _run(self) -> None:
        asyncio.set_event_loop(self.loop)
        self.loop.run_until_complete(self.hub.start())
        self.started.set()
        self.loop.run_forever()

    def __enter__(self) -> _Hub:
        self.thread.start()
        assert self.started.wait(60), "the hub did not start"
        return self

    def call(self, coro):  # type: ignore[no-untyped-def]
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(60)

    def __exit__(self, *exc: object) -> None:
        self.call(self.hub.stop())
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(10)


def test_real_presses_through_a_hub(mini_recording, tmp_path):
    folder, at = mini_recording
    n = 5 + 2 * len(at)
    driver = open_gel("mini", "gelsight-mini", {"source": str(folder), "realtime": False, "rest_frames": 5},
                      max_frames=n - 4)
    cfg = HubConfig(http_port=0, ws_port=0, database=str(tmp_path / "hub.db"), devices=())
    with _Hub(cfg) as h:
        h.call(h.hub._fleet.add_driver(driver, family="gelsight-mini", run=False))
        td = httpx.get(h.hub.td_url("mini"), timeout=10).json()
        assert validate_td(td) == []
        info = td["properties"]["contactInformation"]
        assert "contactRadii" in info["properties"]
        href = info["forms"][0]["href"]
        assert httpx.get(href, timeout=10).json() is None  # unknown: no rest reference yet
        dev = h.hub._fleet.running["mini"]
        h.call(_start(h.hub._fleet, dev))
        deadline = time.monotonic() + 120
        while dev.pipeline.state != "ended" and time.monotonic() < deadline:
            time.sleep(0.2)
        assert dev.pipeline.state == "ended"
        last = httpx.get(href, timeout=10).json()
        assert last["numOfContacts"] == 0 and last["contactRadii"] == []
        assert h.hub._history.writer.flush()
        recs, _ = h.hub._history.reader.rows("mini", 0, 1 << 62, (KIND_PROPERTY, "contactInformation"),
                                             limit=10_000)
        values = [json.loads(r.data) for r in recs]
    touched = [v for v in values if v["numOfContacts"]]
    assert len(touched) == len(at) and all(v["numOfContacts"] == 1 for v in touched)  # 24/24, one each
    # mm; the labels' radii are 1.0-1.7 mm
    assert all(len(v["contactRadii"]) == 1 and 0.7 < v["contactRadii"][0] < 2.2 for v in touched)
    assert len(values) == 1 + 2 * len(at)  # the first "no contact", then each press and its release


async def _start(fleet, dev):  # type: ignore[no-untyped-def]
    """What the hub does for a device once served (``run_all``): attach its history, run it."""
    await fleet._attach(dev)
    fleet._run(dev)
