"""Issue 48 items 7 and 12, against a real hub: raw-signal streams end when their device is removed; a
raw signal's ``/observe`` answers without the SSE ``Accept`` header (a long-poll), which is the form
wotpy 0.18 observes through (it requests a templated href literally: ``.../stream{?maxRate}`` was a
404); ``.../binary/ws`` without an upgrade is a problem+json 400. Each measures a bystander: a press
device's events per second read by an SSE client while the attack runs."""

from __future__ import annotations

import asyncio
import json
import threading
import time

import httpx
import pytest

from wott_hub.config import HubConfig
from wott_hub.network import DiscoveryConfig

from . import surroundings as S

EVENT = "skinDeformedDetection"
CAMERA = {"id": "cam", "family": "flat-vision", "settings": {"source": "sim", "fps": 15.0}}
GRID = {"id": "grid", "family": "taxel-array", "settings": {"simulate": True, "rate_hz": 30.0}}


@pytest.fixture(scope="module")
def hub(hub_thread, press_scene):
    cfg = HubConfig(http_port=0, ws_port=0, history=False, discovery=DiscoveryConfig.off(),
                    devices=(press_scene("pad"),))
    ht = hub_thread(cfg).start()
    yield ht
    ht.stop()


def act(hub, action: str, body: dict) -> httpx.Response:
    return httpx.post(f"{hub.url}/wot/hub/actions/{action}", json=body, timeout=30)


class Reader:
    """A client reading a never-ending response in a thread: how many bytes, and whether it ended."""

    def __init__(self, url: str, headers: dict[str, str] | None = None) -> None:
        self.url, self.headers = url, headers or {}
        self.bytes = 0
        self.status: int | None = None
        self.ended = threading.Event()
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        try:
            with httpx.Client(timeout=httpx.Timeout(10, read=60)) as c, \
                    c.stream("GET", self.url, headers=self.headers) as r:
                self.status = r.status_code
                for data in r.iter_raw():
                    self.bytes += len(data)
                    if self._stop.is_set():
                        return
        except httpx.HTTPError:
            pass
        finally:
            self.ended.set()

    def stop(self) -> None:
        self._stop.set()
        self.thread.join(5)


def rate(meter: S.GapMeter, since: float, until: float) -> float:
    return sum(1 for t in meter.times if since < t <= until) / (until - since)


def test_raw_signal_streams_end_when_their_device_is_removed(hub, eventually):
    """Item 7: 16 streams (images, grids: the stream and the observe forms) end at the removal; before,
    they stayed open and silent for as long as the client waited (30 s in the issue's run)."""
    for body in (CAMERA, GRID):
        assert act(hub, "addDevice", body).status_code == 200
    meter = S.GapMeter(f"{hub.url}/wot/pad/events/{EVENT}").start()
    base = f"{hub.url}/wot"
    sse = {"Accept": "text/event-stream"}
    urls = [(f"{base}/cam/properties/rawImage/stream?maxRate=5", {}),
            (f"{base}/cam/properties/rawImage/observe", sse),
            (f"{base}/grid/properties/pressureGrid/stream?maxRate=5", {}),
            (f"{base}/grid/properties/pressureGrid/observe", sse)] * 4
    handlers = hub.hub._server.ctx.sse  # the open stream handlers
    open_before = len(handlers)
    readers = [Reader(u, h) for u, h in urls]
    try:
        eventually(lambda: all(r.bytes > 0 for r in readers), 30, "every raw stream sends its first frame")
        t0 = time.monotonic()
        for dev in ("cam", "grid"):
            assert act(hub, "removeDevice", {"id": dev}).status_code == 200
        ended = [r.ended.wait(max(0.1, 15 - (time.monotonic() - t0))) for r in readers]
        took = time.monotonic() - t0
        time.sleep(1.0)
        t1 = time.monotonic()
        after = rate(meter, t1 - 1.0, t1)
    finally:
        for r in readers:
            r.stop()
        meter.stop()
    assert all(r.status == 200 for r in readers), [r.status for r in readers]
    assert all(ended), f"{ended.count(False)} of {len(readers)} raw streams open {took:.1f} s after removal"
    assert after > 10, f"the bystander's rate fell to {after:.0f}/s"
    eventually(lambda: len(handlers) <= open_before + 1, 10, "the handlers let go")  # + the bystander


def test_a_raw_signals_observe_form_answers_a_long_poll_and_wotpy_observes_it(hub, eventually):
    """Item 12: ``/observe`` without ``Accept: text/event-stream`` answers one JSON value (it never
    answered); wotpy 0.18 consumes the TD and observes ``pressureGrid`` and ``rawImage`` (it requested
    ``.../stream{?signal,maxRate}`` literally: a 404 on every poll)."""
    for body in (CAMERA, GRID):
        assert act(hub, "addDevice", body).status_code == 200
    try:
        t0 = time.monotonic()
        r = httpx.get(f"{hub.url}/wot/grid/properties/pressureGrid/observe", timeout=30)
        assert r.status_code == 200 and r.headers["Content-Type"].startswith("application/json"), r.text
        grid = r.json()
        assert {"timeStamp", "rows", "cols", "pressure"} <= set(grid)
        r2 = httpx.get(f"{hub.url}/wot/grid/properties/pressureGrid/observe", timeout=30)
        assert r2.json()["timeStamp"] > grid["timeStamp"]  # the next frame, not the same one again
        image = httpx.get(f"{hub.url}/wot/cam/properties/rawImage/observe", timeout=30)
        assert image.status_code == 200 and isinstance(image.json(), str) and len(image.json()) > 100
        assert time.monotonic() - t0 < 25  # each answered: before, none did
        got = asyncio.run(asyncio.wait_for(_wotpy_observes(hub.url), 60))
    finally:
        for dev in ("cam", "grid"):
            act(hub, "removeDevice", {"id": dev})
    assert len(got["pressureGrid"]) >= 2 and all("pressure" in v for v in got["pressureGrid"]), got.keys()
    assert len(got["rawImage"]) >= 1 and all(isinstance(v, str) for v in got["rawImage"])
    assert got["errors"] == [], got["errors"]


async def _wotpy_observes(url: str) -> dict:
    from wotpy.wot.servient import Servient
    from wotpy.wot.wot import WoT

    wot = WoT(servient=Servient(catalogue_port=None))
    out: dict = {"pressureGrid": [], "rawImage": [], "errors": []}
    subs = []
    async with httpx.AsyncClient(timeout=10) as c:
        tds = {t: (await c.get(f"{url}/wot/{t}")).json() for t in ("grid", "cam")}
    for thing_id, name in (("grid", "pressureGrid"), ("cam", "rawImage")):
        thing = wot.consume(json.dumps(tds[thing_id]))
        subs.append(thing.properties[name].subscribe(
            on_next=lambda ev, to=out[name]: to.append(ev.data.value),
            on_error=lambda e: out["errors"].append(repr(e))))
    loop = asyncio.get_running_loop()
    deadline = loop.time() + 30
    while (len(out["pressureGrid"]) < 2 or not out["rawImage"]) and not out["errors"] \
            and loop.time() < deadline:
        await asyncio.sleep(0.1)
    for s in subs:
        s.dispose()
    return out


def test_the_binary_websocket_without_an_upgrade_is_a_problem_json_400(hub):
    r = httpx.get(f"{hub.url}/wot/pad/events/skinDisplacement/binary/ws", timeout=10)
    assert r.status_code == 400 and r.headers["Content-Type"].startswith("application/problem+json"), r.text
    assert "WebSocket" in r.json()["detail"]
