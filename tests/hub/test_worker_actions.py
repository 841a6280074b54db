"""Device actions of devices that run in a worker process (``[hub] workers = 1``), over HTTP.

The same contract as in the hub's process (test_device_actions.py): the TD
declares what the driver can do (its worker reports it), ``tare`` and
``restart`` are invoked from the TD's forms, their effect shows in health and
in history as a ``deviceAction`` event, and a restart keeps the Thing, its
stream and its sequence, and leaves the other devices' streams without a gap.
"""

from __future__ import annotations

import json
import time

import httpx
import pytest

from wott_hub.config import HubConfig
from wott_hub.events.record import KIND_EVENT
from wott_hub.td.validate import validate_payload, validate_td


@pytest.fixture(scope="module")
def live(tmp_path_factory, hub_thread, scene):
    cfg = HubConfig(http_port=0, ws_port=0, database=str(tmp_path_factory.mktemp("wactions") / "hub.db"),
                    workers=1,
                    devices=(scene("pad", "flat", rate_hz=30.0), scene("pad2", "flat", rate_hz=20.0)))
    ht = hub_thread(cfg).start()
    yield ht
    ht.stop()


def _td(live, device):
    return httpx.get(live.hub.td_url(device), timeout=10).json()


def _invoke(td, name):
    form = td["actions"][name]["forms"][0]
    return httpx.request(form["htv:methodName"], form["href"], json={}, timeout=70)


def _health(live, device):
    return httpx.get(f"{live.url}/wot/hub/properties/health", timeout=10).json()["devices"][device]


def _recorded(live, device, name=None):
    assert live.call(lambda: live.hub._history.writer.flush())
    recs, _ = live.hub._history.reader.rows(device, 0, 1 << 62, (KIND_EVENT, name), limit=10**7)
    return recs


def _no_gap(live, device, got):
    ids = [i for i, _, _ in got]
    assert ids == sorted(ids) and len(set(ids)) == len(ids)
    recorded = sorted(r.seq for r in _recorded(live, device))
    assert ids == [s for s in recorded if ids[0] <= s <= ids[-1]], f"gap in {device}'s stream"


def test_a_worker_device_declares_the_actions_its_driver_has(live):
    assert live.hub.devices["pad"].processor is None  # it really runs in the worker
    for device in ("pad", "pad2"):
        td = _td(live, device)
        assert validate_td(td) == []
        assert set(td["actions"]) == {"tare", "restart"}  # as in-process: a scene tares, no calibration
        assert "deviceAction" in td["events"]
        for name, aff in td["actions"].items():
            assert aff["forms"][0]["href"] == f"{live.hub.td_url(device)}/actions/{name}"


def test_tare_in_the_worker_shows_in_health_and_history(live):
    td = _td(live, "pad")
    r = _invoke(td, "tare")
    assert r.status_code == 200, r.text
    out = r.json()
    assert out["device"] == "pad" and out["invokedAction"] == "tare" and out["outcome"] == "ok"
    assert out["detail"] == "a scripted scene has no rest offset: nothing to zero"  # the driver's own
    assert validate_payload(td, "event", "deviceAction", out) == []
    health = _health(live, "pad")
    assert health["tares"] == 1 and health["lastTare"].endswith("Z")
    assert health["lastAction"]["action"] == "tare" and health["lastAction"]["outcome"] == "ok"
    assert out in [json.loads(r.data) for r in _recorded(live, "pad", "deviceAction")]


def test_restart_in_the_worker_keeps_the_stream_and_leaves_the_others_uninterrupted(live, wait_for, run, sse):
    td = _td(live, "pad")
    before = _health(live, "pad")
    own, other = sse(f"{live.hub.td_url('pad')}/events"), sse(f"{live.hub.td_url('pad2')}/events")
    deadline = time.monotonic() + 60  # both streams going before the restart (counted, not timed)
    while (not own.got or len(other.got) <= 5) and time.monotonic() < deadline:
        time.sleep(0.05)
    r = _invoke(td, "restart")
    assert r.status_code == 200, r.text
    assert r.json()["outcome"] == "ok" and r.json()["invokedAction"] == "restart"
    at_own, at_other = len(own.got), len(other.got)
    deadline = time.monotonic() + 60  # a hang's bound: counted events, not a time window
    while (len(own.got) <= at_own + 10 or len(other.got) <= at_other + 10) and time.monotonic() < deadline:
        time.sleep(0.05)
    got_own, got_other = own.stop(), other.stop()
    assert len(got_own) > at_own + 10, "no events after the restart on the same connection"
    assert len(got_other) > at_other + 10 and at_other > 5
    _no_gap(live, "pad", got_own)
    _no_gap(live, "pad2", got_other)
    actions = [json.loads(d) for _, name, d in got_own if name == "deviceAction"]
    assert [a["invokedAction"] for a in actions] == ["restart"]
    assert not [d for _, name, d in got_other if name == "deviceAction"]
    after = _health(live, "pad")
    assert after["restarts"] == before["restarts"] + 1 and after["lastRestart"].endswith("Z")
    assert after["state"] == "ok"
    run(wait_for(lambda: _health(live, "pad")["frames"] > after["frames"], what="frames after the restart"))
    recorded = [json.loads(r.data)["invokedAction"] for r in _recorded(live, "pad", "deviceAction")]
    assert recorded[-1] == "restart"


def test_the_hub_things_restart_device_works_on_a_worker_device(live):
    before = _health(live, "pad2")["restarts"]
    r = httpx.post(f"{live.url}/wot/hub/actions/restartDevice", json={"id": "pad2"}, timeout=70)
    assert r.status_code == 200, r.text
    assert r.json()["device"] == "pad2" and r.json()["outcome"] == "ok"
    assert _health(live, "pad2")["restarts"] == before + 1


def test_an_action_the_worker_device_lacks_is_404(live):
    r = httpx.post(f"{live.hub.td_url('pad')}/actions/recalibrate", json={}, timeout=10)
    assert r.status_code == 404 and "recalibrate" in r.json()["detail"]
    assert r.headers["content-type"].startswith("application/problem+json")


def test_a_worker_that_exited_fails_the_action_with_422_and_records_it(tmp_path, hub_thread, scene, wait_for,
                                                                       run):
    cfg = HubConfig(http_port=0, ws_port=0, database=str(tmp_path / "hub.db"), workers=1,
                    devices=(scene("pad", "flat", rate_hz=30.0),))
    ht = hub_thread(cfg).start()
    try:
        (proc,) = ht.hub._fleet.pool.procs
        proc.kill()
        run(wait_for(lambda: _health(ht, "pad")["state"] == "failed", what="the device failed"))
        r = httpx.post(f"{ht.hub.td_url('pad')}/actions/tare", json={}, timeout=20)
        assert r.status_code == 422, r.text
        assert r.headers["content-type"].startswith("application/problem+json")
        assert "worker process exited" in r.json()["detail"]
        health = _health(ht, "pad")
        assert health["lastAction"]["action"] == "tare" and health["lastAction"]["outcome"] == "failed"
        recorded = [json.loads(r.data) for r in _recorded(ht, "pad", "deviceAction")]
        assert recorded[-1]["outcome"] == "failed" and "worker process exited" in recorded[-1]["detail"]
    finally:
        ht.stop()
