"""The real Mini presses through a real hub (a recording as ``source``): the TD declares contactRadii,
contactInformation is null until the rest reference, then every press is one contact and the background
none, in history as the clients saw it."""

from __future__ import annotations

import asyncio
import json
import threading
import time

import httpx
import numpy as np
from wott_driver_gel.evaluation import write_recording
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
        assert info["properties"]["contactForces"]["description"].startswith("Always empty")
        assert "depthMap" not in td["properties"]  # no calibration, no depth
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


def test_a_calibrated_gel_serves_its_depth_map_and_force_estimates(mini, tmp_path):
    from wott_driver_gel.depth import calibrate

    train = np.arange(0, 24, 2)
    cal = calibrate(mini.background, mini.presses[train], mini.centres_px[train], mini.radii_px[train],
                    ball_radius_mm=2.0, mm_per_px=mini.mm_per_px)
    cal.save(tmp_path / "depth.npz")
    write_recording(tmp_path / "f", mini.background, mini.presses[1:8:2], between=2)
    driver = open_gel("mini", "gelsight-mini", {"source": str(tmp_path / "f"), "realtime": False,
                                                "calibration": str(tmp_path / "depth.npz")}, max_frames=13)
    cfg = HubConfig(http_port=0, ws_port=0, database=str(tmp_path / "hub.db"), devices=())
    with _Hub(cfg) as h:
        h.call(h.hub._fleet.add_driver(driver, family="gelsight-mini", run=False))
        td = httpx.get(h.hub.td_url("mini"), timeout=10).json()
        assert validate_td(td) == []
        depth = td["properties"]["depthMap"]
        assert depth["@type"] == "tac:DepthMap" and "depth" in depth["properties"]
        forces = td["properties"]["contactInformation"]["properties"]["contactForces"]["description"]
        assert forces.startswith("An estimate, not a measurement")
        dev = h.hub._fleet.running["mini"]
        h.call(_start(h.hub._fleet, dev))
        deadline = time.monotonic() + 120
        while dev.pipeline.state != "ended" and time.monotonic() < deadline:
            time.sleep(0.2)
        grid = httpx.get(depth["forms"][0]["href"], timeout=10).json()
        assert (grid["rows"], grid["cols"]) == (120, 160) and len(grid["depth"]) == 120
        assert h.hub._history.writer.flush()
        recs, _ = h.hub._history.reader.rows("mini", 0, 1 << 62, (KIND_PROPERTY, "contactInformation"),
                                             limit=1000)
    touched = [v for r in recs if (v := json.loads(r.data))["numOfContacts"]]
    assert len(touched) == 4
    assert all(0 < -v["contactForces"][0]["z"] < 50 for v in touched)  # N, into the gel


def test_a_gel_in_a_worker_process_is_unknown_until_its_reference(mini, tmp_path):
    """The hub keeps the contacts of a device run by a worker process (``[hub] workers``): unknown (null)
    there too until the worker's first frame with a reference, then what the worker measured."""
    from wott_hub.plugins import DeviceConfig

    write_recording(tmp_path / "f", mini.background, mini.presses[:2])
    device = DeviceConfig("mini", "gelsight-mini", {"source": str(tmp_path / "f"), "fps": 1.0})
    cfg = HubConfig(http_port=0, ws_port=0, database=str(tmp_path / "hub.db"), workers=1, devices=(device,))
    with _Hub(cfg) as h:
        td = httpx.get(h.hub.td_url("mini"), timeout=10).json()
        href = td["properties"]["contactInformation"]["forms"][0]["href"]
        seen = [httpx.get(href, timeout=10).json()]  # 5 rest frames at 1 frame/s: 4 s before a reference
        deadline = time.monotonic() + 90
        while not (seen[-1] or {}).get("numOfContacts") and time.monotonic() < deadline:
            time.sleep(0.2)
            seen.append(httpx.get(href, timeout=10).json())
    assert seen[0] is None
    assert seen[-1]["numOfContacts"] == 1 and len(seen[-1]["contactRadii"]) == 1
