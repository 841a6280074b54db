"""The hub Thing's history actions on a running hub, used over HTTP and from wott-client:
devices and ranges, records as JSON Lines with a limit and paging, MCAP export, errors as
problem+json naming the field; the replay action's device group, name filter and offset."""

from __future__ import annotations

import asyncio
import json

import httpx
import pytest
from mcap.reader import make_reader
from wott_client import AsyncClient, Client

from wott_hub.config import HubConfig
from wott_hub.events.record import KIND_NAMES


@pytest.fixture(scope="module")
def live(tmp_path_factory, hub_thread, scene):
    cfg = HubConfig(http_port=0, ws_port=0, database=str(tmp_path_factory.mktemp("hist") / "hub.db"),
                    devices=(scene("pad", "flat"), scene("pad2", "flat", rate_hz=60.0)))
    ht = hub_thread(cfg).start()

    async def recorded() -> None:
        while ht.hub._history.writer.committed.get("pad2", 0) < 150:
            await asyncio.sleep(0.05)

    ht.call(recorded)
    yield ht
    ht.stop()


@pytest.fixture(scope="module")
def hub_td(live):
    return httpx.get(f"{live.url}/wot/hub", timeout=10).json()


def _href(td, name):
    return td["actions"][name]["forms"][0]["href"]


def _schemas_typed(schema, path="input"):
    """Every (sub)schema declares a type (node-wot and wotpy need one)."""
    assert "type" in schema, path
    for k, sub in (schema.get("properties") or {}).items():
        _schemas_typed(sub, f"{path}.{k}")
    if isinstance(schema.get("items"), dict):
        _schemas_typed(schema["items"], f"{path}[]")


def test_the_hub_td_declares_the_history_actions_with_typed_schemas(hub_td):
    for name in ("historyDevices", "historyRecords", "historyExport", "replay"):
        aff = hub_td["actions"][name]
        _schemas_typed(aff["input"])
        _schemas_typed(aff["output"], "output")
        assert aff["forms"][0]["op"] == ["invokeaction"]
    form = hub_td["actions"]["historyRecords"]["forms"][0]
    assert form["response"]["contentType"] == "application/x-ndjson"
    assert hub_td["actions"]["historyRecords"]["safe"] is True
    assert {"withDevices", "names", "offset"} <= set(hub_td["actions"]["replay"]["input"]["properties"])


def test_devices_and_a_page_of_records_match_the_database(live, hub_td):
    devices = {d["id"]: d for d in httpx.post(_href(hub_td, "historyDevices"), json={}, timeout=10).json()}
    assert devices["pad"]["count"] > 0 and devices["pad"]["from"] <= devices["pad"]["to"]
    lo = devices["pad"]["from"]
    resp = httpx.post(_href(hub_td, "historyRecords"), json={"device": "pad", "from": str(lo), "limit": 40,
                                                              "names": ["skinDeformedDetection"]}, timeout=10)
    assert resp.status_code == 200 and resp.headers["content-type"].startswith("application/x-ndjson")
    lines = [json.loads(x) for x in resp.text.splitlines()]
    pages = live.hub._history.reader.pages("pad", lo, None, ["skinDeformedDetection"])
    want = [(r.seq, r.t_ns, r.kind, r.name, r.data) for page in pages for r in page][:80]
    assert [(x["seq"], x["t_ns"], x["kind"], x["name"], json.dumps(x["data"], separators=(",", ":")))
            for x in lines] == [(s, t, KIND_NAMES[k], n, json.dumps(json.loads(d), separators=(",", ":")))
                                for s, t, k, n, d in want[:40]]
    # paging: the next page starts after the last seq
    nxt = httpx.post(_href(hub_td, "historyRecords"), json={"device": "pad", "from": lo, "limit": 40,
                                                             "names": ["skinDeformedDetection"],
                                                             "after": lines[-1]["seq"]}, timeout=10)
    assert [json.loads(x)["seq"] for x in nxt.text.splitlines()] == [r[0] for r in want[40:80]]


@pytest.mark.parametrize(("body", "status", "field"), [
    ({}, 400, "'device'"),
    ({"device": "pad", "limit": 0}, 400, "'limit'"),
    ({"device": "pad", "limit": "ten"}, 400, "'limit'"),
    ({"device": "pad", "names": "skinDeformedDetection"}, 400, "'names'"),
    ({"device": "pad", "from": "yesterday-ish"}, 400, "yesterday-ish"),
    ({"device": "pad", "from": "now", "to": "-1h"}, 400, "'from'"),
    ({"device": "nope"}, 404, "nope"),
])
def test_bad_input_is_a_problem_naming_the_field(hub_td, body, status, field):
    resp = httpx.post(_href(hub_td, "historyRecords"), json=body, timeout=10)
    assert resp.status_code == status
    assert resp.headers["content-type"].startswith("application/problem+json")
    assert field in resp.json()["detail"]


def test_export_bad_input_and_not_json(hub_td):
    resp = httpx.post(_href(hub_td, "historyExport"), json={"devices": []}, timeout=10)
    assert resp.status_code == 400 and "'devices'" in resp.json()["detail"]
    resp = httpx.post(_href(hub_td, "historyExport"), json={"devices": ["pad"], "sceneHz": 0}, timeout=10)
    assert resp.status_code == 400 and "'sceneHz'" in resp.json()["detail"]
    resp = httpx.post(_href(hub_td, "historyDevices"), content=b"{nope", timeout=10)
    assert resp.status_code == 400 and "JSON" in resp.json()["detail"]


def test_the_client_lists_pages_and_exports_mcap(live, hub_td, tmp_path):
    with Client() as client:
        history = client.history(f"{live.url}/wot/hub")
        devices = {d["id"]: d for d in history.devices()}
        hi = devices["pad2"]["to"]
        recs = list(history.records("pad2", t_to=hi, names=["contactInformation"], limit=25))
        assert len(recs) == 25 and all(r["name"] == "contactInformation" for r in recs)
        assert [r["seq"] for r in recs] == sorted(r["seq"] for r in recs)
        everything = list(history.records("pad2", t_to=hi))
        with pytest.raises(Exception, match="nope"):
            list(history.records("nope"))
        path = tmp_path / "x.mcap"
        size = history.export_mcap(path, ["pad", "pad2"], t_to=hi, scene_hz=10)
    assert size == path.stat().st_size > 0
    with path.open("rb") as f:
        msgs = [(ch.topic, m.log_time, m.data) for _, ch, m in make_reader(f).iter_messages()]
    pad2 = [(t, d) for topic, t, d in msgs if topic.startswith(("/pad2/events/", "/pad2/properties/"))]
    assert pad2 == [(r["t_ns"], json.dumps(r["data"], separators=(",", ":"), ensure_ascii=False).encode())
                    for r in everything]
    assert any(topic == "/pad/scene/deformation" for topic, *_ in msgs)


def test_the_async_client_pages_in_small_pages(live):
    async def main():
        async with AsyncClient() as client:
            history = await client.async_history(f"{live.url}/wot/hub")
            return [r["seq"] async for r in history.async_records("pad", limit=55, page=10)]

    seqs = asyncio.run(main())
    assert len(seqs) == 55 and len(set(seqs)) == 55 and seqs == sorted(seqs)


def test_the_replay_action_plays_a_device_group_filtered_from_an_offset(live, hub_td, sse_events):
    devices = {d["id"]: d for d in httpx.post(_href(hub_td, "historyDevices"), json={}, timeout=10).json()}
    lo = devices["pad"]["from"]
    resp = httpx.post(_href(hub_td, "replay"), json={
        "device": "pad", "withDevices": ["pad2"], "names": ["contactInformation"], "offset": 0.5,
        "speed": 4, "from": lo}, timeout=10)
    assert resp.status_code == 200, resp.text
    out = resp.json()
    assert out["things"] == ["replay-pad", "replay-pad2"]
    td2 = httpx.get(f"{live.url}/wot/replay-pad2", timeout=10).json()
    assert td2["title"].endswith("(replay)")
    got = sse_events(f"{live.url}/wot/replay-pad2/properties/contactInformation/observe", 3,
                     headers={"Last-Event-ID": "0"})
    assert len(got) == 3  # the filtered affordance arrives on the second Thing of the group
    bad = httpx.post(_href(hub_td, "replay"), json={"device": "pad", "offset": -1}, timeout=10)
    assert bad.status_code == 400 and "'offset'" in bad.json()["detail"]
    bad = httpx.post(_href(hub_td, "replay"), json={"device": "pad", "withDevices": "pad2"}, timeout=10)
    assert bad.status_code == 400 and "'withDevices'" in bad.json()["detail"]
    stopped = httpx.post(_href(hub_td, "stopReplay"), json={"thing": "replay-pad2"}, timeout=10).json()
    assert stopped["stopped"] is True
    assert httpx.get(f"{live.url}/wot/replay-pad", timeout=10).status_code == 404  # the group stops as one
