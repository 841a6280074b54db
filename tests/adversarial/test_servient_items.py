"""Issue 16 item 10, the servient's parts, against a real hub on 127.0.0.1: OPTIONS on the hub's
routes, wotpy's HTTP routes (read-only PUT, unknown names), WebSocket messages that are too deep or
name no Thing, the per-connection subscription cap, and unknown paths. Every error is a 4xx
problem+json naming what was wrong, answered within a timeout."""

from __future__ import annotations

import asyncio
import json
from typing import Any

import httpx
import pytest
from tornado.httpclient import HTTPClientError
from tornado.websocket import WebSocketClientConnection, websocket_connect

from wott_hub.servient.ws import MAX_SUBSCRIPTIONS

PROBLEM = "application/problem+json"


@pytest.fixture(scope="module")
def hub(hub_thread, press_scene):
    from wott_hub.config import HubConfig

    ht = hub_thread(HubConfig(http_port=0, ws_port=0, history=False, devices=(press_scene("pad"),))).start()
    yield ht
    ht.stop()


@pytest.fixture(scope="module")
def http(hub):
    with httpx.Client(base_url=hub.url, timeout=30) as c:  # a hang's bound, not a speed
        yield c


def ws_url(hub, name: str) -> str:
    return f"ws://127.0.0.1:{hub.hub._server.ws_port}/{name}"


def assert_problem(resp: httpx.Response, status: int, *words: str) -> dict[str, Any]:
    assert resp.status_code == status, resp.text
    assert resp.headers["Content-Type"].startswith(PROBLEM), resp.headers
    body = resp.json()
    assert body["status"] == status and body["instance"] == resp.request.url.path
    for word in words:
        assert word in body["detail"], body
    return body


def rpc(method: str, msg_id: int, **params: Any) -> str:
    return json.dumps({"jsonrpc": "2.0", "method": method, "params": params, "id": msg_id})


async def recv(ws: WebSocketClientConnection, timeout: float = 30) -> Any:
    """The next message, decoded; the connection must still be open."""
    raw = await asyncio.wait_for(ws.read_message(), timeout)
    assert raw is not None, "the hub closed the connection"
    return json.loads(raw)


def test_options_on_every_hub_route_is_a_cors_preflight_answer(http):
    preflight = {"Origin": "http://example.org", "Access-Control-Request-Method": "GET"}
    for path in ("/wot", "/wot/pad", "/wot/pad/properties", "/wot/pad/properties/skinMaterial",
                 "/wot/pad/properties/contactInformation/observe", "/wot/pad/events",
                 "/wot/pad/events/actionDetection", "/pad/property/skinMaterial",
                 "/pad/event/actionDetection/subscription"):
        r = http.options(path, headers=preflight)
        assert r.status_code == 204, (path, r.text)
        assert r.headers["Access-Control-Allow-Origin"] == "*"
        assert "GET" in r.headers["Access-Control-Allow-Methods"]


def test_a_put_to_a_read_only_property_on_wotpys_route_answers_405_at_once(http):
    for path in ("/pad/property/skinMaterial", "/wot/pad/properties/skinMaterial"):
        r = http.put(path, json={"materialType": "steel"})  # answered (it used to hang): no timeout
        assert_problem(r, 405, "skinMaterial", "read-only")
        assert r.headers["Allow"].startswith("GET")
    assert_problem(http.put("/pad/property/skinMaterial", content=b"{not json"), 400, "not JSON")
    unchanged = http.get("/wot/pad/properties/skinMaterial").json()
    assert http.get("/pad/property/skinMaterial").json() == unchanged and unchanged["materialType"] != "steel"


def test_unknown_thing_property_action_or_event_on_wotpys_routes_is_a_404_naming_it(http):
    assert_problem(http.get("/nosuch/property/skinMaterial"), 404, "'nosuch'")
    assert_problem(http.get("/pad/property/nosuch"), 404, "property 'nosuch'")
    assert_problem(http.put("/pad/property/nosuch", json=1), 404, "property 'nosuch'")
    assert_problem(http.get("/pad/property/nosuch/subscription"), 404, "property 'nosuch'")
    assert_problem(http.post("/pad/action/nosuch", json={}), 404, "action 'nosuch'")
    assert_problem(http.get("/pad/event/nosuch/subscription"), 404, "event 'nosuch'")
    # an action the hub serves on its own route, not on wotpy's: not a 500 either
    assert_problem(http.post("/hub/action/replay", json={}), 404, "'replay'", "not served on this route")
    # and the hub's own routes name the missing piece the same way
    assert_problem(http.get("/wot/nosuch"), 404, "'nosuch'")
    assert_problem(http.get("/wot/pad/properties/nosuch"), 404, "'nosuch'")
    assert_problem(http.get("/wot/pad/events/nosuch"), 404, "'nosuch'")


def test_unknown_paths_answer_a_problem_json_404(http):
    for path in ("/nosuch", "/wot/pad/nosuch/deeper", "/favicon.ico", "/a/b/c/d"):
        assert_problem(http.get(path), 404, path)
    assert_problem(http.post("/nosuch", json={}), 404, "/nosuch")


def test_a_deep_or_broken_websocket_message_gets_an_error_and_keeps_the_connection(hub, http):
    async def main() -> None:
        ws = await websocket_connect(ws_url(hub, "pad"), connect_timeout=30)
        try:
            deep = '{"a":' * 5000 + "1" + "}" * 5000
            deep_param = rpc("read_property", 1, name="x")[:-1] + ',"deep":' + deep + "}"
            no_name = json.dumps({"jsonrpc": "2.0", "method": "read_property", "params": {}, "id": 2})
            for bad in ["[" * 100_000 + "]" * 100_000, deep_param, "{", "[]", no_name]:
                await ws.write_message(bad)
                reply = await recv(ws)
                assert reply["error"]["code"] in (-32700, -32600, -32602), reply
            await ws.write_message(rpc("read_property", 3, name="skinMaterial"))
            reply = await recv(ws)
            assert reply["id"] == 3 and reply["result"] == http.get("/wot/pad/properties/skinMaterial").json()
        finally:
            ws.close()
        # a URL naming no Thing is refused at the handshake, as a problem+json 404
        with pytest.raises(HTTPClientError) as e:
            await websocket_connect(ws_url(hub, "nosuch"), connect_timeout=30)
        assert e.value.code == 404 and e.value.response is not None
        assert e.value.response.headers["Content-Type"] == PROBLEM
        assert "Unknown Thing 'nosuch'" in json.loads(e.value.response.body)["detail"]

    asyncio.run(main())


def test_one_websocket_holds_at_most_the_documented_number_of_subscriptions(hub, http):
    async def main() -> None:
        ws = await websocket_connect(ws_url(hub, "pad"), connect_timeout=30)
        try:
            for i in range(MAX_SUBSCRIPTIONS + 20):
                await ws.write_message(rpc("on_event", i, name="skinDeformedDetection"))
            sids, refused = [], []
            while len(sids) + len(refused) < MAX_SUBSCRIPTIONS + 20:
                msg = await recv(ws, 30)
                if "subscription" in msg:
                    continue  # an event of a subscription already made
                (sids if "result" in msg else refused).append(msg)
            assert len(sids) == MAX_SUBSCRIPTIONS and len(refused) == 20
            err = refused[0]["error"]
            assert err["code"] == -32600 and str(MAX_SUBSCRIPTIONS) in err["message"]
            assert err["data"] == {"maxSubscriptions": MAX_SUBSCRIPTIONS}
            # the hub stays responsive for everybody else
            assert (await asyncio.to_thread(http.get, "/wot/pad")).status_code == 200
            # disposing one frees a place
            await ws.write_message(rpc("dispose", 9999, subscription=sids[0]["result"]))
            await ws.write_message(rpc("on_event", 10000, name="actionDetection"))
            got: dict[int, Any] = {}
            while 10000 not in got:
                msg = await recv(ws, 30)
                if "id" in msg and "subscription" not in msg:
                    got[msg["id"]] = msg
            assert got[9999]["result"] == sids[0]["result"] and "result" in got[10000]
        finally:
            ws.close()

    asyncio.run(main())
