"""Device actions in every Tactile TD (``tare``, ``restart``, ``recalibrate``), invoked over HTTP.

A real hub on loopback with scene devices; clients follow the TD's forms (plain
HTTP, and wotpy's client). What an action did shows in the device's health and
in its history (a ``deviceAction`` event); ``restart`` keeps the Thing, its
stream and its sequence: an SSE client connected across it sees no gap.
"""

from __future__ import annotations

import asyncio
import json
import time

import httpx
import pytest

from wott_hub.config import HubConfig
from wott_hub.events.record import KIND_EVENT
from wott_hub.td.actions import DEVICE_ACTIONS
from wott_hub.td.builder import tactile_context
from wott_hub.td.validate import validate_payload, validate_td


@pytest.fixture(scope="module")
def live(tmp_path_factory, hub_thread, scene):
    cfg = HubConfig(http_port=0, ws_port=0, database=str(tmp_path_factory.mktemp("actions") / "hub.db"),
                    devices=(scene("pad", "flat", rate_hz=30.0), scene("pad2", "flat", rate_hz=20.0)))
    ht = hub_thread(cfg).start()
    yield ht
    ht.stop()


def _td(live, device):
    return httpx.get(live.hub.td_url(device), timeout=10).json()


def _invoke(td, name, body=None):
    form = td["actions"][name]["forms"][0]
    assert form["op"] == ["invokeaction"] and form["htv:methodName"] == "POST"
    return httpx.request(form["htv:methodName"], form["href"], json=body if body is not None else {},
                         timeout=20)


def _health(live, device):
    return httpx.get(f"{live.url}/wot/hub/properties/health", timeout=10).json()["devices"][device]


def _recorded(live, device, name):
    assert live.hub._history.writer.flush()
    recs, _ = live.hub._history.reader.rows(device, 0, 1 << 62, (KIND_EVENT, name), limit=10**7)
    return recs


def test_every_device_td_declares_its_actions_with_typed_schemas_and_http_forms(live):
    for device in ("pad", "pad2"):
        td = _td(live, device)
        assert validate_td(td) == []
        assert set(td["actions"]) == {"tare", "restart"}  # a scene driver tares; no calibration to redo
        for name, aff in td["actions"].items():
            assert aff["input"]["type"] == "object" and aff["output"]["type"] == "object"
            assert all("type" in s for s in aff["output"]["properties"].values())
            (form,) = aff["forms"]
            assert form == {"href": f"{live.hub.td_url(device)}/actions/{name}", "op": ["invokeaction"],
                            "htv:methodName": "POST", "contentType": "application/json"}
        assert "deviceAction" in td["events"]
    ctx = tactile_context()["@context"]
    data = td["events"]["deviceAction"]["data"]
    assert {"deviceAction", "DeviceAction", *data["properties"]} <= set(ctx)
    assert set(DEVICE_ACTIONS) <= set(ctx)


def test_tare_over_http_shows_in_health_history_and_the_event_stream(live, sse_events):
    td = _td(live, "pad")
    r = _invoke(td, "tare")
    assert r.status_code == 200, r.text
    out = r.json()
    assert out["device"] == "pad" and out["invokedAction"] == "tare" and out["outcome"] == "ok"
    # resumed from the start of the device's stream: the actions of earlier tests, then this one
    url = f"{live.hub.td_url('pad')}/events/deviceAction"
    n = len(_recorded(live, "pad", "deviceAction"))
    got = [json.loads(e.data) for e in sse_events(url, n, headers={"Last-Event-ID": "0"})]
    assert got[-1] == out
    assert validate_payload(td, "event", "deviceAction", out) == []
    health = _health(live, "pad")
    assert health["tares"] >= 1 and health["lastTare"].endswith("Z")
    assert health["lastAction"]["action"] == "tare" and health["lastAction"]["outcome"] == "ok"
    assert live.hub.devices["pad"].driver.tares >= 1  # the driver was asked
    recorded = [json.loads(r.data) for r in _recorded(live, "pad", "deviceAction")]
    assert out in recorded


def test_restart_reopens_the_driver_and_keeps_the_stream_and_its_sequence(live, sse):
    td = _td(live, "pad")
    before = _health(live, "pad")
    old_driver = live.hub.devices["pad"].driver
    stream = sse(f"{live.hub.td_url('pad')}/events")  # every event of the device, one connection
    time.sleep(0.3)
    r = _invoke(td, "restart")
    assert r.status_code == 200, r.text
    assert r.json()["outcome"] == "ok"
    restarted_at = len(stream.got)
    deadline = time.monotonic() + 60  # a hang's bound: counted events, not a time window
    while len(stream.got) <= restarted_at + 10 and time.monotonic() < deadline:
        time.sleep(0.05)
    got = stream.stop()
    assert len(got) > restarted_at + 10, "no events after the restart on the same connection"
    ids = [i for i, _, _ in got]
    assert ids == sorted(ids) and len(set(ids)) == len(ids)
    assert live.hub._history.writer.flush()
    recs, _ = live.hub._history.reader.rows("pad", 0, 1 << 62, (KIND_EVENT, None), limit=10**7)
    recorded = sorted(r.seq for r in recs)
    assert ids == [s for s in recorded if ids[0] <= s <= ids[-1]], "gap in the stream across the restart"
    actions = [json.loads(d) for _, name, d in got if name == "deviceAction"]
    assert [a["invokedAction"] for a in actions] == ["restart"]  # on the same stream, in order
    assert live.hub.devices["pad"].driver is not old_driver
    after = _health(live, "pad")
    assert after["restarts"] == before["restarts"] + 1 and "lastRestart" in after
    assert after["state"] == "ok" and after["frames"] > before["frames"]


def test_mistakes_get_problem_json_naming_what_is_wrong(live):
    base = live.hub.td_url("pad")
    r = httpx.post(f"{live.url}/wot/nosuch/actions/tare", json={}, timeout=10)
    assert r.status_code == 404 and "nosuch" in r.json()["detail"]
    assert r.headers["content-type"].startswith("application/problem+json")
    r = httpx.post(f"{base}/actions/recalibrate", json={}, timeout=10)
    assert r.status_code == 404 and "recalibrate" in r.json()["detail"] and "tare" in r.json()["detail"]
    r = httpx.post(f"{base}/actions/tare", content=b"{nope", timeout=10)
    assert r.status_code == 400 and "JSON" in r.json()["detail"]
    r = httpx.post(f"{base}/actions/tare", json=[1], timeout=10)
    assert r.status_code == 400 and "object" in r.json()["detail"]


def test_a_wotpy_client_invokes_tare_from_the_td(live):
    from wotpy.wot.servient import Servient
    from wotpy.wot.wot import WoT

    async def main():
        wot = WoT(servient=Servient(catalogue_port=None))
        thing = await wot.consume_from_url(live.hub.td_url("pad2"))
        return await asyncio.wait_for(thing.invoke_action("tare", {}), 20)

    out = asyncio.run(main())
    assert out["device"] == "pad2" and out["invokedAction"] == "tare" and out["outcome"] == "ok"
    assert _health(live, "pad2")["tares"] == 1


async def _open(family: str, settings: dict):
    from wott_hub.plugins import DeviceConfig
    from wott_hub.runtime.opening import open_driver

    return await open_driver(DeviceConfig(f"{family}-x", family, settings))


@pytest.mark.parametrize("family", ["flat-vision", "barrel-vision"])
def test_vision_drivers_take_a_new_reference_on_tare_and_find_the_grid_again_on_recalibrate(family, run):
    from wott_hub.runtime.capabilities import action_names
    from wott_hub.td.builder import build_tactile_td

    async def main():
        driver = await _open(family, {"source": "sim", "fps": 30.0})
        refs = []
        try:
            n = 0
            async for _ in driver.frames():
                n += 1
                if n in (1, 2):  # the reference is taken from the first frame
                    refs.append(driver.estimator.reference_px)
                    assert (driver.tare if n == 1 else driver.recalibrate)()
                if n == 3:
                    refs.append(driver.estimator.reference_px)
                    break
        finally:
            await driver.close()
        return driver, refs

    driver, (first, tared, recalibrated) = run(main())
    assert tared is not first and recalibrated is not tared  # a new reference each time
    assert "failed" not in driver.health().reason
    names = action_names(driver, reopenable=True)
    assert names == ("tare", "restart", "recalibrate")
    assert set(build_tactile_td(driver.description, actions=names)["actions"]) == set(names)


def test_taxel_tare_zeroes_the_offsets_at_the_current_readings(run):
    import numpy as np

    async def main():
        driver = await _open("taxel-array", {"simulate": True})
        out = []
        try:
            async for frame in driver.frames():
                peak = float(np.abs(frame.displacement).max())
                if out or peak > 0:  # the demo scene presses: tare under load
                    out.append(peak)
                    if len(out) == 1:
                        driver.tare()
                if len(out) == 4:
                    break
        finally:
            await driver.close()
        return driver, out

    driver, (pressed, tared, *later) = run(main(), timeout=30)
    assert pressed > 0 and tared == 0.0  # the frame read at the tare is the new zero
    zero = driver.readings.zero
    assert zero is not None and zero.max() > 0  # ... the press's counts, subtracted
    assert len(later) == 2 and all(p >= 0 for p in later)
