"""node-wot 0.9.2 against a hub with tokens: what its clients send, and the TD forms it works with.

``nodewot_credentials.mjs matrix`` measures, against a local recorder, which credentials node-wot
puts on a property read, an SSE subscription and a long-poll subscription for each kind of
``securityDefinitions``; the assertions below are that table (docs/security.md, "node-wot").
``nodewot_credentials.mjs hub`` then consumes a secured hub's TDs as they are served (no link
edited): with the token given by ``servient.addCredentials`` and a subscription as its first call,
node-wot receives events and observes ``contactInformation`` over the ``longpoll`` forms the hub
puts first in a secured TD (``wott_hub.security.policy``), and reads every property; with a wrong
token it gets nothing.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import httpx
import pytest

from wott_hub.td.validate import validate_td

HERE = Path(__file__).resolve().parent
TOKEN = "Bearer wott_00000000_measure"
HEADER = {"authorization": TOKEN, "access_token": None}
BARE = {"authorization": "wott_00000000_measure", "access_token": None}  # apikey: no scheme
NOTHING = {"authorization": None, "access_token": None}


def _run(node_wot: list[str], *args: str) -> dict:
    done = subprocess.run([*node_wot, str(HERE / "nodewot_credentials.mjs"), *args], cwd=HERE,
                          capture_output=True, text=True, timeout=180)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def matrix(node_wot) -> dict:
    return _run(node_wot, "matrix")["matrix"]


def _sent(step: dict) -> list[tuple[str, dict]]:
    return [(r["method"], {"authorization": r["authorization"], "access_token": r["access_token"]})
            for r in step["requests"]]


@pytest.mark.parametrize(("variant", "credential"), [
    ("bearer/header", HEADER), ("bearer/query", HEADER),  # `in` is ignored: always the header
    ("apikey/header", BARE), ("apikey/query", BARE),  # the key alone, in Authorization
])
def test_node_wot_signs_reads_and_long_polls_never_sse(matrix, variant, credential):
    got = matrix[variant]
    assert got["read"]["first"]["ok"] and _sent(got["read"]["first"]) == [("GET", credential)]
    sse = got["sse"]
    assert sse["first"]["ok"] and _sent(sse["first"]) == [("GET", NOTHING)]  # new EventSource(href)
    assert _sent(sse["thenRead"]) == [("GET", credential)]
    poll = got["longpoll"]["first"]  # no htv:methodName: a HEAD handshake, then GETs
    assert poll["ok"] and _sent(poll)[0] == ("HEAD", credential)
    assert len(_sent(poll)) >= 2 and all(s == ("GET", credential) for s in _sent(poll)[1:])
    with_get = got["longpoll, htv:methodName GET"]["first"]  # the handshake takes the declared method
    assert with_get["ok"] and {m for m, _ in _sent(with_get)} == {"GET"}


def test_node_wot_applies_no_combo_and_no_form_level_scheme(matrix):
    for client, got in matrix["combo"].items():
        assert {c["authorization"] for c in got["first"]["requests"]} == {None}, client
    # the Thing's scheme is the header, the stream form names its own: a first call on that form
    # leaves node-wot's client without credentials for every later request, reads included
    for client in ("sse", "longpoll"):
        got = matrix["bearer/header, stream form combo"][client]
        assert all(s == NOTHING for _, s in _sent(got["first"]))
        assert _sent(got["thenRead"]) == [("GET", NOTHING)]
        got = matrix["bearer/header, stream form bearer/header"][client]
        assert got["first"]["error"] == "No Bearer credentials for Thing"  # addCredentials' list, unread
        assert _sent(got["thenRead"]) == [("GET", NOTHING)]


@pytest.fixture(scope="module")
def secured(tmp_path_factory, hub_thread, press_scene):
    """A hub with tokens (required on loopback too) serving one pressing device; (hub, read token)."""
    from wott_hub.config import HubConfig
    from wott_hub.network import DiscoveryConfig
    from wott_hub.security import Scope, SecurityConfig, TokenFile

    f = TokenFile(tmp_path_factory.mktemp("secured") / "tokens.json")
    token = f.create("node-wot", Scope.READ)[0]
    hub = hub_thread(HubConfig(http_port=0, ws_port=0, history=False, devices=(press_scene("pad"),),
                               discovery=DiscoveryConfig.off(), name="secured",
                               security=SecurityConfig(tokens_file=str(f.path)))).start()
    yield hub, token
    hub.stop()


def test_a_secured_td_offers_node_wot_a_long_poll_first(secured):
    hub, token = secured
    auth = {"Authorization": f"Bearer {token}"}
    assert httpx.get(f"{hub.url}/wot/pad").status_code == 401
    for thing in ("pad", "hub"):
        td = httpx.get(f"{hub.url}/wot/{thing}", headers=auth).json()
        assert td["security"] == ["bearer_sc"] and validate_td(td, tactile=thing == "pad") == [], thing
        affordances = [*td.get("events", {}).items(), *td.get("properties", {}).items()]
        streams = [(name, aff["forms"]) for name, aff in affordances
                   if any(f.get("subprotocol") for f in aff["forms"])]
        assert streams, thing
        for name, forms in streams:
            subprotocols = [f.get("subprotocol") for f in forms if f["href"].startswith("http")
                            and f.get("subprotocol") != "stream"]  # skinDisplacement's binary stream (#29)
            assert subprotocols[-2:] == ["longpoll", "sse"], (thing, name, subprotocols)
            poll, sse = (f for f in forms if f.get("subprotocol") in ("longpoll", "sse"))
            assert "security" not in poll and "htv:methodName" not in poll and poll["href"] == sse["href"]
            assert sse["security"] == ["bearer_either_sc"] and poll["op"] == sse["op"]
            head = httpx.head(poll["href"], headers=auth)  # node-wot's handshake
            assert head.status_code == 200 and head.headers["content-type"] == "application/json"
            assert httpx.head(poll["href"]).status_code == 401


def test_node_wot_subscribes_first_then_reads_a_secured_hub_without_editing_links(secured, node_wot):
    hub, token = secured
    got = _run(node_wot, "hub", hub.url, token, "pad", "20")
    report = got["hub"]
    assert report["errors"] == [] and report["security"] == ["bearer_sc"], report
    assert report["first"] == "skinDeformedDetection"  # the call that used to leave it without credentials
    for name in ("skinDeformedDetection", "actionDetection", "actionDetails"):
        got_event = report["events"][name]
        assert got_event["n"] >= 1 and got_event["bad"] is None, (name, report["events"])
    assert report["events"]["deviceAction"]["bad"] is None  # subscribed (nothing tared: no notification)
    assert report["observe"]["n"] >= 1 and report["observe"]["bad"] is None, report["observe"]
    assert report["read"] and all(v == "object" for v in report["read"].values()), report["read"]
    assert got["refused"] == {"td": "TD: HTTP 401", "subscribe": "Client error: Unauthorized"}


def test_the_validators_pass_a_secured_hubs_tds(secured, node_wot, shared_data, tmp_path):
    """The playground (validate_tds.mjs, as in test_td_validators.py) on the TDs of a hub with tokens:
    valid, 0 failed assertions; of the defaults, besides readOnly/writeOnly inside values, only the
    bearer schemes' ``alg`` is not stated (the tokens are opaque: no algorithm applies)."""
    hub, token = secured
    auth = {"Authorization": f"Bearer {token}"}
    context_url = f"{hub.url}/contexts/tactile-v1.jsonld"
    (tmp_path / "tactile.jsonld").write_bytes(httpx.get(context_url).content)  # public, as the docs say
    td11 = str(shared_data / "w3c" / "td-context-1.1.jsonld")
    tds = {thing: httpx.get(f"{hub.url}/wot/{thing}", headers=auth).json() for thing in ("pad", "hub")}
    (tmp_path / "input.json").write_text(json.dumps({"tds": tds, "contexts": {
        "https://www.w3.org/2019/wot/td/v1": td11, "https://www.w3.org/2022/wot/td/v1.1": td11,
        context_url: str(tmp_path / "tactile.jsonld")}}))
    done = subprocess.run([*node_wot, str(HERE / "validate_tds.mjs"), str(tmp_path / "input.json")], cwd=HERE,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    for line in done.stdout.splitlines()[:-1]:
        got = json.loads(line)
        report = got["report"]
        assert report["json"] == report["schema"] == report["jsonld"] == report["additional"] == "passed", got
        assert got["assertions"]["fail"] == [], got["assertions"]
        left = got["defaults"]["besidesValueReadWriteOnly"]
        assert {e["path"].split("/")[2] for e in left} == {"bearer_sc", "bearer_query_sc"}, left
        assert {e["params"].get("missingProperty") for e in left if e["keyword"] == "required"} >= {"alg"}

