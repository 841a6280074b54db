"""The twin's static files and the hub Thing's replay actions, over plain HTTP (no browser)."""

from __future__ import annotations

import json
import time
from importlib import resources

import httpx
import pytest

from wott_hub.td.validate import validate_td


@pytest.fixture(scope="module")
def http(twin):
    with httpx.Client(base_url=twin.url, timeout=20) as c:
        yield c


def test_root_serves_the_fleet_page_and_its_modules(http):
    r = http.get("/")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    assert '<script type="module" src="/twin/fleet.js">' in r.text
    for name in ("fleet.js", "device.js", "wot.js", "skin.js", "replay.js", "render3d.js"):
        r = http.get(f"/twin/{name}")
        assert r.status_code == 200 and r.headers["content-type"].startswith("text/javascript"), name
    assert http.get("/twin/device.html").headers["content-type"].startswith("text/html")
    assert http.get("/twin/nothing.js").status_code == 404


def test_three_js_is_vendored_with_its_licence_and_served_compressed(http):
    """The device page's renderer ships in the package (nothing fetched at run time)."""
    vendor = resources.files("wott_hub.web") / "static" / "vendor"
    shipped = (vendor / "three.module.min.js").read_bytes()
    r = http.get("/twin/vendor/three.module.min.js", headers={"Accept-Encoding": "gzip"})
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/javascript")
    assert r.headers["content-encoding"] == "gzip" and r.content == shipped  # httpx decodes the gzip body
    assert int(r.headers["content-length"]) < len(shipped) / 2
    again = http.get("/twin/vendor/three.module.min.js", headers={"If-None-Match": r.headers["etag"]})
    assert again.status_code == 304 and again.content == b""
    plain = http.get("/twin/vendor/three.module.min.js", headers={"Accept-Encoding": "identity"})
    assert "content-encoding" not in plain.headers and plain.content == shipped
    controls = http.get("/twin/vendor/OrbitControls.js")
    assert controls.status_code == 200 and 'from "./three.module.min.js"' in controls.text
    licence = http.get("/twin/vendor/three.LICENSE")
    assert licence.headers["content-type"].startswith("text/plain") and "MIT License" in licence.text
    assert "plotly" not in http.get("/twin/device.html").text  # no longer on the device page
    assert http.get("/twin/vendor/nothing.js").status_code == 404


def test_hub_thing_declares_replay_actions_with_post_forms(twin, http):
    td = http.get("/wot/hub").json()
    assert validate_td(td, tactile=False) == []
    for name in ("replay", "stopReplay"):
        (form,) = td["actions"][name]["forms"]
        assert form["op"] == ["invokeaction"] and form["htv:methodName"] == "POST"
        assert form["href"] == f"{twin.url}/wot/hub/actions/{name}"
    assert td["actions"]["replay"]["input"]["required"] == ["device"]


def test_replay_action_replays_history_as_a_thing_and_stop_removes_it(twin, http, sse_events):
    td = http.get("/wot/hub").json()
    replay = td["actions"]["replay"]["forms"][0]["href"]
    stop = td["actions"]["stopReplay"]["forms"][0]["href"]
    # what is replayed must be in history first: deformed packets of a press (the hub may have just started)
    sse_events(f"{twin.hub.td_url('barrel')}/events/skinDeformedDetection", 5, timeout=20)
    assert twin.hub._history.writer.flush()
    deadline = time.monotonic() + 10
    while True:  # the busy barrel has recorded events within a second or two
        r = httpx.post(replay, json={"device": "barrel", "from": "-30s", "speed": 0}, timeout=20)
        if r.status_code == 200 or time.monotonic() > deadline:
            break
        time.sleep(0.2)
    assert r.status_code == 200, r.text
    out = r.json()
    assert out["thing"] == "replay-barrel" and out["from"] > 0 and out["speed"] == 0
    events = f"{out['td']}/events/skinDeformedDetection"
    got = [json.loads(ev.data)
           for ev in sse_events(events, 5, headers={"Last-Event-ID": str(out["after"])}, timeout=20)]
    assert all(p["numOfDeformedNodes"] == len(p["arrayOfDeformedNodes"]) for p in got)
    assert got[0]["timeStamp"] >= out["from"]  # recorded packets, unchanged
    assert "replay-barrel" in {d["id"] for d in http.get("/wot/hub/properties/devices").json()}
    r = httpx.post(stop, json={"thing": "replay-barrel"})
    assert r.status_code == 200 and r.json()["stopped"] is True
    assert http.get("/wot/replay-barrel").status_code == 404
    assert httpx.post(stop, json={"device": "barrel"}).json() == {"stopped": False, "emitted": 0}


@pytest.mark.parametrize(("body", "status"), [
    ({}, 400),
    ({"device": "barrel", "speed": -1}, 400),
    ({"device": "barrel", "from": "yesterday-ish"}, 400),
    ({"device": "barrel", "from": "-1s", "to": "-10s"}, 400),
    ({"device": "barrel", "loop": "yes"}, 400),
    ({"device": "no-such-device"}, 404),
])
def test_replay_action_refuses_bad_input_with_problem_json(http, body, status):
    r = http.post("/wot/hub/actions/replay", json=body)
    assert r.status_code == status
    assert r.headers["content-type"] == "application/problem+json" and r.json()["status"] == status


def test_replay_action_answers_cors_preflight(http):
    r = http.options("/wot/hub/actions/replay", headers={"Origin": "http://elsewhere",
                                                         "Access-Control-Request-Method": "POST"})
    assert r.status_code == 204 and "POST" in r.headers["access-control-allow-methods"]
    assert r.headers["access-control-allow-origin"] == "*"
