"""A real hub on loopback with simulated devices, used by real clients.

TDs over HTTP against TD 1.1 + Tactile + interop rules; properties; a wotpy
client over WebSocket; SSE clients, including one that disconnects mid-stream
and resumes with Last-Event-ID: no gap and no duplicate, checked against history.
"""

from __future__ import annotations

import asyncio
import json
import time

import httpx
import pytest

from wott_hub.config import HubConfig
from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY
from wott_hub.td.builder import tactile_context
from wott_hub.td.validate import validate_payload, validate_td

DEVICES = {"barrel": "barrel", "pad": "flat", "cyl": "cylinder"}


def _start_live(hub_thread, scene, database: str):
    cfg = HubConfig(http_port=0, ws_port=0, database=database, ring_size=16,
                    devices=tuple(scene(i, shape) for i, shape in DEVICES.items()))
    return hub_thread(cfg).start()


@pytest.fixture(scope="module")
def live_sqlite(tmp_path_factory, hub_thread, scene):
    ht = _start_live(hub_thread, scene, str(tmp_path_factory.mktemp("live") / "hub.db"))
    yield ht
    ht.stop()


@pytest.fixture(scope="module")
def live_postgresql(pg_cluster, hub_thread, scene):
    """The same hub recording into PostgreSQL (tests/postgres.py); started only if a test asks."""
    name = pg_cluster.create_schema("live")
    ht = _start_live(hub_thread, scene, pg_cluster.url(schema=name))
    yield ht
    ht.stop()
    pg_cluster.drop_schema(name)


@pytest.fixture
def live(request):
    """The hub of this module: on SQLite, or on the engine a test parametrizes (indirect)."""
    return request.getfixturevalue(f"live_{getattr(request, 'param', 'sqlite')}")


ENGINES = pytest.mark.parametrize("live", ["sqlite", "postgresql"], indirect=True)
"""The tests that read history back (SSE resume) run on both engines."""


@pytest.fixture(scope="module")
def http(live_sqlite):
    with httpx.Client(base_url=live_sqlite.hub.http_url, timeout=10) as c:
        yield c


def test_every_served_td_is_valid_and_names_a_served_context(live, http):
    catalogue = http.get("/wot").json()
    assert set(catalogue) == {*DEVICES, "hub"}
    for thing_id, path in catalogue.items():
        r = http.get(path)
        assert r.status_code == 200 and r.headers["content-type"].startswith("application/td+json")
        td = r.json()
        assert validate_td(td, tactile=thing_id != "hub") == [], thing_id
        ctx = td["@context"]
        assert ctx[:2] == ["https://www.w3.org/2019/wot/td/v1", "https://www.w3.org/2022/wot/td/v1.1"]
        if thing_id != "hub":
            served = httpx.get(ctx[2])
            assert served.status_code == 200 and served.json() == tactile_context()
        for kind in ("properties", "events"):
            for aff in td.get(kind, {}).values():
                for form in aff["forms"]:
                    assert "op" in form and "contentType" in form
                    assert form["href"].startswith(("http://", "ws://"))  # wotpy needs absolute hrefs
                    if form["href"].startswith("http"):
                        assert form["htv:methodName"] == "GET"
                    if form.get("contentType") == "text/event-stream":
                        assert form["subprotocol"] == "sse"
    assert http.get("/wot/pad", headers={"If-None-Match": http.get("/wot/pad").headers["etag"]}
                    ).status_code == 304


def test_properties_are_read_over_http(live, http):
    td = http.get("/wot/barrel").json()
    nodes = http.get("/wot/barrel/properties/skinNodes").json()
    assert nodes["numOfNodes"] == live.hub.devices["barrel"].processor.mesh.n_nodes == 707
    cells = http.get("/wot/barrel/properties/skinCells").json()
    assert cells["numOfCells"] == len(cells["arrayOfCells"]) > 0
    for name in td["properties"]:
        value = http.get(f"/wot/barrel/properties/{name}").json()
        assert validate_payload(td, "property", name, value) == [], name
    everything = http.get("/wot/pad/properties").json()
    assert set(everything) == set(td["properties"])
    r = http.get("/wot/pad/properties/nope")
    assert r.status_code == 404 and r.headers["content-type"] == "application/problem+json"
    assert http.get("/wot/nope").status_code == 404


def test_hub_thing_lists_devices_health_and_counters(live, http, eventually):
    devices = http.get("/wot/hub/properties/devices").json()
    assert {d["id"] for d in devices} == set(DEVICES)
    assert all(httpx.get(d["td"]).status_code == 200 for d in devices)
    health = http.get("/wot/hub/properties/health").json()
    assert set(health["devices"]) == set(DEVICES) and health["history"]["enabled"]
    def counted():
        counters = http.get("/wot/hub/properties/eventCounters").json()
        return counters["things"]["pad"]["published"] > 0 and counters["history"]["written"] > 0

    eventually(counted, what="a published and a committed event counted")  # the writer's first commit


@pytest.fixture(scope="module")
def sse(sse_events):
    """The first n events of a stream as (id, name, data), asserting its Content-Type."""
    def read(url, n, headers=None):
        return [(int(ev.id), ev.event, ev.data)
                for ev in sse_events(url, n, headers=headers, timeout=10, assert_content_type=True)]

    return read


def _recorded(live, device, kind, name=None):
    writer, reader = live.hub._history.writer, live.hub._history.reader
    assert writer.flush()
    recs, _ = reader.rows(device, 0, 1 << 62, (kind, name), limit=10**7)
    return {r.seq: r for r in recs}


@ENGINES
def test_sse_resume_with_last_event_id_loses_nothing_and_repeats_nothing(live, sse):
    url = f"{live.hub.td_url('pad')}/events"  # every event of the device
    first = sse(url, 40)
    time.sleep(0.5)  # the device keeps publishing while the client is away (> ring_size records)
    last_id = first[-1][0]
    second = sse(url, 120, headers={"Last-Event-ID": str(last_id)})
    got = first + second
    ids = [i for i, _, _ in got]
    assert len(ids) == len(set(ids)), "duplicate events"
    assert ids == sorted(ids)
    recorded = _recorded(live, "pad", KIND_EVENT)
    expected = [s for s in sorted(recorded) if ids[0] <= s <= ids[-1]]
    assert ids == expected, "gap: the resumed stream differs from history"
    for i, name, data in got:
        assert recorded[i].name == name and recorded[i].data == data


@ENGINES
def test_one_event_stream_resumes_from_history_too(live, sse):
    url = f"{live.hub.td_url('cyl')}/events/skinDeformedDetection"
    first = sse(url, 10)
    time.sleep(0.3)
    second = sse(url, 60, headers={"Last-Event-ID": str(first[-1][0])})
    ids = [i for i, _, _ in first + second]
    recorded = _recorded(live, "cyl", KIND_EVENT, "skinDeformedDetection")
    assert ids == [s for s in sorted(recorded) if ids[0] <= s <= ids[-1]]
    td = httpx.get(live.hub.td_url("cyl")).json()
    assert all(validate_payload(td, "event", "skinDeformedDetection", json.loads(d)) == []
               for _, _, d in second[:5])


@ENGINES
def test_contact_information_is_observable_over_sse(live, sse):
    url = f"{live.hub.td_url('pad')}/properties/contactInformation/observe"
    got = sse(url, 5)
    assert all(name == "message" for _, name, _ in got)  # one affordance: unnamed (docs/hub.md, SSE)
    td = httpx.get(live.hub.td_url("pad")).json()
    assert all(validate_payload(td, "property", "contactInformation", json.loads(d)) == [] for *_, d in got)
    recorded = _recorded(live, "pad", KIND_PROPERTY, "contactInformation")
    assert all(recorded[i].data == d for i, _, d in got)


def test_a_client_without_sse_gets_one_event_per_request(live):
    r = httpx.get(f"{live.hub.td_url('pad')}/events/skinDeformedDetection", timeout=10)
    assert r.status_code == 200 and r.headers["content-type"] == "application/json"
    assert "arrayOfDeformedNodes" in r.json() and int(r.headers["x-event-id"]) > 0


def test_a_wotpy_client_reads_properties_and_subscribes_over_websocket(live):
    from wotpy.wot.servient import Servient
    from wotpy.wot.wot import WoT

    async def main():
        wot = WoT(servient=Servient(catalogue_port=None))
        thing = await wot.consume_from_url(live.hub.td_url("pad"))
        shape = await thing.read_property("skinShape")
        events, changes = [], []
        done = asyncio.Event()

        def on_event(ev):
            events.append(ev.data)
            if len(events) >= 20 and changes:
                done.set()

        def on_change(ev):
            changes.append(ev.data.value)

        subs = [thing.events["skinDeformedDetection"].subscribe(on_next=on_event),
                thing.properties["contactInformation"].subscribe(on_next=on_change)]
        try:
            await asyncio.wait_for(done.wait(), 15)
        finally:
            for s in subs:
                s.dispose()
        return shape, events, changes

    shape, events, changes = asyncio.run(main())
    assert shape["shapeType"] == "rectangularPrism"
    td = httpx.get(live.hub.td_url("pad")).json()
    assert all(validate_payload(td, "event", "skinDeformedDetection", e) == [] for e in events)
    assert validate_payload(td, "property", "contactInformation", changes[0]) == []


def test_websocket_json_rpc_errors_follow_wotpy(live):
    from tornado.websocket import websocket_connect

    async def main():
        ws = await websocket_connect(f"{live.hub.ws_url}/pad")
        replies = []
        for msg in ("not json", json.dumps({"jsonrpc": "2.0", "method": "nope", "params": {}, "id": 1}),
                    json.dumps({"jsonrpc": "2.0", "method": "read_property", "params": {}, "id": 2}),
                    json.dumps({"jsonrpc": "2.0", "method": "read_property", "params": {"name": "x"},
                                "id": 3}),
                    json.dumps({"jsonrpc": "2.0", "method": "read_property",
                                "params": {"name": "skinMaterial"}, "id": 4}),
                    json.dumps({"jsonrpc": "2.0", "method": "write_property",
                                "params": {"name": "skinMaterial", "value": {}}, "id": 5})):
            await ws.write_message(msg)
            replies.append(json.loads(await asyncio.wait_for(ws.read_message(), 5)))
        ws.close()
        return replies

    parse, method, params, unknown, ok, write = asyncio.run(main())
    assert parse["error"]["code"] == -32700
    assert method["error"]["code"] == -32600
    assert params["error"]["code"] == -32602 and params["id"] == 2
    assert unknown["id"] == 3 and "error" in unknown
    material = {"materialType": "ecoflex", "materialShoreHardness": "Shore 00-50"}
    assert ok == {"jsonrpc": "2.0", "result": material, "id": 4}
    assert write["id"] == 5 and "error" in write  # read-only, as wotpy says


def test_history_records_each_device_td_and_static_values_as_served(live):
    for device in DEVICES:
        served = live.hub._server.things.get(device)
        info = live.hub._history.reader.thing_info(device)
        assert info["td"] == served.td
        assert info["static_values"] == {k: json.loads(v) for k, v in served.static.items()}
        assert "skinNodes" in info["static_values"]


def test_a_replay_that_cannot_be_served_leaves_nothing_behind(live):
    hub = live.hub

    async def replay_as_pad_in_capitals():  # "Pad" and "pad" share a WebSocket URL
        with pytest.raises(ValueError, match="Pad"):  # bad input: the replay action answers 400
            await hub.add_replay("pad", thing_id="Pad")
        return "Pad" in hub._plane.streams, "Pad" in hub.replays, "Pad" in hub._server.things.by_id

    assert live.call(replay_as_pad_in_capitals) == (False, False, False)
    assert httpx.get(hub.td_url("pad")).status_code == 200
