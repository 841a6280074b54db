"""Property-based fuzzing (hypothesis) of the hub's servient against a real hub on 127.0.0.1: the
HTTP property, action and TD routes (the hub's and wotpy's), the SSE routes (odd names, methods,
``Last-Event-ID`` values) and the WebSocket JSON-RPC endpoint (random and deep messages).

Never a 500, never a hang (every request has a timeout), every HTTP error a problem+json, every
WebSocket request answered on a connection that stays open; afterwards a TD GET answers within
``BOUND_S``. Bounded ``max_examples`` keep the file within ~40 s."""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Iterator
from urllib.parse import quote

import httpx
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from tornado.httpclient import HTTPClientError
from tornado.websocket import websocket_connect

BOUND_S = 30.0
"""How long "still answers" may take: a hang's bound, not a speed (a loaded machine answers late;
a hub that no longer answers never does). Timings belong to benchmarks."""
TIMEOUT = httpx.Timeout(60.0)
FUZZ = settings(max_examples=150, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])


@pytest.fixture(scope="module")
def hub(hub_thread, press_scene, tmp_path_factory):
    from wott_hub.config import HubConfig

    db = tmp_path_factory.mktemp("fuzz") / "hub.db"
    cfg = HubConfig(http_port=0, ws_port=0, database=str(db), devices=(press_scene("pad"),))
    ht = hub_thread(cfg).start()
    yield ht
    try:
        with httpx.Client(base_url=ht.url, timeout=TIMEOUT) as c:
            still_answers(c)
        assert ht.thread.is_alive()
    finally:
        ht.stop()


@pytest.fixture(scope="module")
def http(hub) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=hub.url, timeout=TIMEOUT) as client:
        yield client
        still_answers(client)


def still_answers(client: httpx.Client) -> None:
    start = time.monotonic()
    resp = client.get("/wot/pad")
    assert resp.status_code == 200 and resp.json()["title"]
    assert time.monotonic() - start < BOUND_S


def check(resp: httpx.Response) -> None:
    """No 5xx; an error is a problem+json with its status."""
    assert resp.status_code < 500, (resp.request.method, resp.request.url, resp.status_code, resp.text[:300])
    if resp.status_code >= 400:
        assert resp.headers["Content-Type"].startswith("application/problem+json"), resp.text[:300]
        if resp.request.method != "HEAD":
            assert resp.json()["status"] == resp.status_code


# --- strategies ------------------------------------------------------------------------------------

things = st.one_of(st.sampled_from(["pad", "hub", "nosuch", "PAD", "pad ", "..", "%00"]),
                   st.text(max_size=12))
properties = st.one_of(st.sampled_from(["skinMaterial", "skinNodes", "contactInformation", "health",
                                        "devices", "eventCounters", "nosuch", ""]), st.text(max_size=12))
events = st.one_of(st.sampled_from(["actionDetection", "skinDeformedDetection", "healthChange", "nosuch"]),
                   st.text(max_size=12))
actions = st.one_of(st.sampled_from(["replay", "stopReplay", "nosuch"]), st.text(max_size=12))
json_values = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(), st.floats(allow_nan=False, allow_infinity=False),
              st.text(max_size=20)),
    lambda inner: st.one_of(st.lists(inner, max_size=4),
                            st.dictionaries(st.text(max_size=8), inner, max_size=4)),
    max_leaves=12)
replay_inputs = st.fixed_dictionaries({}, optional={
    "device": st.one_of(st.sampled_from(["pad", "nosuch", ""]), json_values),
    "thing": st.one_of(st.sampled_from(["pad", "nosuch"]), json_values),
    "from": st.one_of(st.sampled_from(["-10s", "2020-01-01T00:00:00Z", "garbage", "1e400"]), json_values),
    "to": st.one_of(st.sampled_from(["now", "-1s", "1e300"]), json_values),
    "speed": st.one_of(st.sampled_from([0, -1, 1e308, 0.5]), json_values),
    "loop": json_values})
bodies = st.one_of(
    st.none(),
    json_values.map(lambda v: json.dumps(v).encode()),
    replay_inputs.map(lambda v: json.dumps(v).encode()),
    st.integers(10, 3000).map(lambda n: b"[" * n + b"]" * n),
    st.binary(max_size=64))
methods = st.sampled_from(["GET", "PUT", "POST", "DELETE", "PATCH", "OPTIONS", "HEAD"])


def seg(s: str) -> str:
    return quote(s, safe="") or "%20"


interaction_paths = st.one_of(
    st.sampled_from(["/wot/pad/properties/skinMaterial", "/wot/hub/properties/health",
                     "/pad/property/skinNodes", "/hub/property/devices", "/wot/hub/actions/replay",
                     "/wot/hub/actions/stopReplay", "/hub/action/replay", "/wot/pad", "/wot/hub", "/wot"]),
    st.tuples(things, properties).map(lambda t: f"/wot/{seg(t[0])}/properties/{seg(t[1])}"),
    things.map(lambda t: f"/wot/{seg(t)}/properties"),
    things.map(lambda t: f"/wot/{seg(t)}"),
    st.tuples(things, properties).map(lambda t: f"/{seg(t[0])}/property/{seg(t[1])}"),
    st.tuples(things, actions).map(lambda t: f"/{seg(t[0])}/action/{seg(t[1])}"),
    actions.map(lambda a: f"/wot/hub/actions/{seg(a)}"),
    st.tuples(things, st.text(max_size=12)).map(lambda t: f"/{seg(t[0])}/property/{seg(t[1])}x/subscription"),
    st.tuples(things, st.text(max_size=12)).map(lambda t: f"/{seg(t[0])}/event/{seg(t[1])}x/subscription"),
    st.lists(st.text(max_size=8), max_size=5).map(lambda parts: "/" + "/".join(seg(p) for p in parts)))


# --- HTTP: properties, actions, TDs ----------------------------------------------------------------

@FUZZ
@given(method=methods, path=interaction_paths, body=bodies,
       content_type=st.sampled_from(["application/json", "text/plain", "application/merge-patch+json"]))
def test_property_action_and_td_routes_never_fail_or_hang(http, method, path, body, content_type) -> None:
    check(http.request(method, path, content=body if method in ("PUT", "POST", "PATCH") else None,
                       headers={"Content-Type": content_type}))


# --- SSE -------------------------------------------------------------------------------------------

last_event_ids = st.one_of(st.none(), st.integers(-2**70, 2**70).map(str),
                           st.sampled_from(["", " ", "1e3", "-1", "0x10", "١٢", "9" * 400, "nan"]),
                           st.text(max_size=20))
stream_paths = st.one_of(
    st.sampled_from(["/wot/pad/events", "/wot/pad/events/skinDeformedDetection",
                     "/wot/pad/events/actionDetection", "/wot/pad/properties/contactInformation/observe",
                     "/wot/hub/events"]),
    st.tuples(things, events).map(lambda t: f"/wot/{seg(t[0])}/events/{seg(t[1])}"),
    things.map(lambda t: f"/wot/{seg(t)}/events"),
    st.tuples(things, properties).map(lambda t: f"/wot/{seg(t[0])}/properties/{seg(t[1])}/observe"))


@settings(FUZZ, max_examples=80)
@given(path=stream_paths, last_id=last_event_ids, in_query=st.booleans(),
       accept=st.sampled_from(["text/event-stream"] * 4 + ["*/*", "application/json"]),
       method=st.sampled_from(["GET", "GET", "GET", "POST", "PUT", "OPTIONS", "HEAD"]))
def test_sse_routes_never_fail_or_hang(http, path, last_id, in_query, accept, method) -> None:
    headers = {"Accept": accept}
    params = {}
    if last_id is not None:
        if last_id != last_id.strip() or not all(" " <= c <= "~" for c in last_id):  # not a header value
            in_query = True
        if in_query:
            params["lastEventId"] = last_id
        else:
            headers["Last-Event-ID"] = last_id
    try:
        # the stream's first line comes at once (a loaded machine: late); a long poll (a GET without
        # the SSE Accept) waits for a record, so give it less: it may time out, and only it may
        poll = method == "GET" and "text/event-stream" not in accept
        timeout = httpx.Timeout(BOUND_S, read=1.5 if poll else BOUND_S)
        with http.stream(method, path, headers=headers, params=params, timeout=timeout) as r:
            if r.status_code == 200 and "text/event-stream" in r.headers.get("content-type", ""):
                if method == "HEAD":  # a stream (the directory's, the hub's) answers HEAD without a body
                    assert r.read() == b""
                    return
                first = next(r.iter_raw())  # the stream opens at once with a retry: field
                assert first.startswith((b"retry:", b"id:", b"event:"))
                return
            r.read()
    except httpx.ReadTimeout:
        # a long poll (no text/event-stream) of a valid stream waits for its next record: allowed,
        # but only there
        assert method == "GET" and "text/event-stream" not in accept, path
        return
    check(r)


# --- WebSocket JSON-RPC ----------------------------------------------------------------------------

rpc_methods = st.one_of(st.sampled_from(["read_property", "write_property", "invoke_action",
                                         "on_property_change", "on_event", "on_td_change", "dispose"]),
                        st.text(max_size=10), json_values)
params = st.one_of(
    st.fixed_dictionaries({}, optional={"name": st.one_of(properties, events, actions, json_values),
                                        "value": json_values, "parameters": json_values,
                                        "subscription": st.one_of(st.text(max_size=36), json_values)}),
    json_values)
requests = st.one_of(
    st.fixed_dictionaries({"jsonrpc": st.sampled_from(["2.0", "2.0", "1.0", 2])},
                          optional={"method": rpc_methods, "params": params,
                                    "id": st.one_of(st.integers(), st.text(max_size=8), json_values)}
                          ).map(json.dumps),
    st.integers(10, 50_000).map(lambda n: "[" * n + "]" * n),
    st.integers(10, 50_000).map(lambda n: '{"jsonrpc":"2.0","method":"read_property","params":{"name":'
                                + "[" * n + "]" * n + '},"id":1}'),
    st.text(max_size=40))


@settings(FUZZ, max_examples=80)
@given(name=st.one_of(st.sampled_from(["pad", "hub"]), things),
       messages=st.lists(requests, min_size=1, max_size=6))
def test_websocket_messages_never_drop_the_connection(hub, name, messages) -> None:
    url = f"ws://127.0.0.1:{hub.hub._server.ws_port}/{seg(name)}"

    async def main() -> None:
        try:
            ws = await websocket_connect(url, connect_timeout=BOUND_S)
        except HTTPClientError as e:  # a URL naming no Thing: refused at the handshake
            assert e.code == 404 and e.response is not None and b"Unknown Thing" in e.response.body
            return
        try:
            for m in messages:
                await ws.write_message(m)
            await ws.write_message(json.dumps({"jsonrpc": "2.0", "method": "read_property",
                                               "params": {"name": "nosuch"}, "id": "sentinel"}))
            deadline = time.monotonic() + BOUND_S
            while True:  # every reply is JSON; the sentinel's comes after the others' on this socket
                raw = await asyncio.wait_for(ws.read_message(), max(0.1, deadline - time.monotonic()))
                assert raw is not None, "the hub closed the connection"
                msg = json.loads(raw)
                if isinstance(msg, dict) and msg.get("id") == "sentinel":
                    assert "error" in msg
                    break
        finally:
            ws.close()

    asyncio.run(main())
