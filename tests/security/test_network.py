"""Every route of a hub bound to a non-loopback address, from a client in another network namespace.

What the TDs declare is what the server does (issue 17): without credentials every
route the TDs name answers 401 with ``WWW-Authenticate``; a ``read`` token reads
only, ``control`` also invokes actions, ``admin`` also writes into the directory;
WebSockets take the token at the handshake; TLS serves https/wss and a client
trusting another CA is refused; nothing secret reaches the log or the history.
"""

from __future__ import annotations

import json
import sqlite3
import subprocess

import pytest

from wott_hub.security import Scope, TokenFile
from wott_hub.security.tls import write_selfsigned

from .conftest import NS_IP, WOTT_HUB, HubProcess, in_ns, wait_for

ORIGIN = "http://lab.example:3000"


def _toml(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int | float):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {_toml(x)}" for k, x in v.items()) + "}"
    return "[" + ", ".join(_toml(x) for x in v) + "]"


def write_config(d, host: str, security: str) -> str:
    from wott_hub.examples import example_device
    from wott_hub.plugins.demo import _demo_steps

    steps = _demo_steps(example_device("flat").mesh)
    (d / "hub.toml").write_text(f"""
[hub]
name = "sec"
host = "{host}"
http_port = 0
ws_port = 0
database = "hub.db"
history_batch_ms = 20

[discovery]
mdns = false
browse = false

{security}

[[device]]
id = "pad"
family = "scene"
shape = "flat"
loop = true
rate_hz = 30.0
step = {_toml(steps)}
""")
    return str(d / "hub.toml")


@pytest.fixture(scope="module")
def tokens(tmp_path_factory):
    d = tmp_path_factory.mktemp("sec")
    f = TokenFile(d / "tokens.json")
    made = {scope: f.create(f"{scope}-client", Scope.parse(scope))[0]
            for scope in ("read", "control", "admin")}
    return d, made


@pytest.fixture(scope="module")
def hub(netns, tokens):
    d, _ = tokens
    cfg = write_config(d, netns[1], f'[security]\ntokens_file = "tokens.json"\ncors_origins = ["{ORIGIN}"]')
    proc = HubProcess(["-c", cfg], d)
    try:
        token, http = tokens[1]["read"], proc.info["http"]
        td = in_ns(netns[0], [{"id": "td", "method": "GET", "url": f"{http}/wot/hub", "token": token}])["td"]
        proc.hub_id = json.loads(td["body"])["id"]
        yield proc
    finally:
        proc.stop()


def _routes(hub: HubProcess) -> dict[str, tuple[str, str]]:
    """Every route the hub's TDs and the directory name, by a label: (method, url)."""
    info = {**hub.info, "hub_id": hub.hub_id}
    http, ws = info["http"], info["websocket"]
    return {
        "catalogue": ("GET", f"{http}/wot"), "hub TD": ("GET", f"{http}/wot/hub"),
        "device TD": ("GET", f"{http}/wot/pad"),
        "properties": ("GET", f"{http}/wot/pad/properties"),
        "property": ("GET", f"{http}/wot/hub/properties/health"),
        "observe (SSE)": ("GET", f"{http}/wot/hub/properties/health/observe"),
        "events (SSE)": ("GET", f"{http}/wot/pad/events"),
        "one event (SSE)": ("GET", f"{http}/wot/pad/events/actionDetection"),
        "wotpy property": ("GET", f"{http}/hub/property/health"),
        "action replay": ("POST", f"{http}/wot/hub/actions/replay"),
        "action stopReplay": ("POST", f"{http}/wot/hub/actions/stopReplay"),
        "directory TD": ("GET", f"{http}/.well-known/wot"),
        "things": ("GET", f"{http}/things"), "thing": ("GET", f"{http}/things/{info['hub_id']}"),
        "search": ("GET", f"{http}/search/jsonpath?query=$"), "directory events": ("GET", f"{http}/events"),
        "directory write": ("PUT", f"{http}/things/urn:test:x"),
        "WebSocket": ("WS", f"{ws}/pad"),
    }


def _ask(ns, routes, token=None, **extra) -> dict:
    reqs = []
    for label, (method, url) in routes.items():
        r = {"id": label, "method": "GET" if method == "WS" else method, "url": url, "token": token,
             "ws": method == "WS", "sse": "SSE" in label or label == "directory events", **extra}
        if method in ("POST", "PUT"):
            r["body"] = {"device": "pad", "from": "-5s"} if "replay" in label else _foreign_td()
        reqs.append(r)
    return in_ns(ns, reqs)


def _foreign_td() -> dict:
    return {"@context": "https://www.w3.org/2022/wot/td/v1.1", "id": "urn:test:x", "title": "x",
            "securityDefinitions": {"n": {"scheme": "nosec"}}, "security": "n"}


def test_every_route_without_credentials_is_401_with_www_authenticate(netns, hub):
    got = _ask(netns[0], _routes(hub))
    assert {k: v.get("status") for k, v in got.items()} == {k: 401 for k in got}
    for label, r in got.items():
        if label != "WebSocket":  # a refused handshake's headers are not kept by the client
            assert r["www"].startswith('Bearer realm="wott-hub"'), label
    bad = _ask(netns[0], {"hub TD": ("GET", f"{hub.info['http']}/wot/hub")}, token="wott_00000000_nope")
    assert bad["hub TD"]["status"] == 401 and 'error="invalid_token"' in bad["hub TD"]["www"]


def test_read_token_reads_only(netns, hub, tokens):
    got = _ask(netns[0], _routes(hub), token=tokens[1]["read"])
    status = {k: v.get("status") for k, v in got.items()}
    writes = {"action replay", "action stopReplay", "directory write"}
    assert {k for k, s in status.items() if s == 403} == writes, status
    # the directory's event stream sends its headers with the first event: admitted, it waits (a
    # refused one is answered at once, above)
    events = got.pop("directory events")
    assert events.get("status") == 200 or "timed out" in events["error"], events
    assert {k: got[k] for k in got if k not in writes and status[k] not in (101, 200)} == {}
    assert 'error="insufficient_scope", scope="control"' in got["action replay"]["www"]
    assert 'scope="admin"' in got["directory write"]["www"]


def test_control_token_invokes_actions_but_does_not_write_the_directory(netns, hub, tokens):
    routes = _routes(hub)
    got = _ask(netns[0], {k: routes[k] for k in ("action replay", "directory write", "hub TD")},
               token=tokens[1]["control"])
    assert got["action replay"]["status"] == 200, got["action replay"]
    assert "pad" in got["action replay"]["body"]
    assert got["directory write"]["status"] == 403
    assert got["hub TD"]["status"] == 200


def test_safe_actions_need_read_fleet_actions_admin(netns, hub, tokens):
    http, made = hub.info["http"], tokens[1]
    history = f"{http}/wot/hub/actions/historyDevices"
    remove = f"{http}/wot/hub/actions/removeDevice"
    got = in_ns(netns[0], [
        {"id": "history read", "method": "POST", "url": history, "token": made["read"], "body": {}},
        {"id": "history anonymous", "method": "POST", "url": history, "body": {}},
        {"id": "remove control", "method": "POST", "url": remove, "token": made["control"],
         "body": {"id": "no-such-device"}},
        {"id": "remove admin", "method": "POST", "url": remove, "token": made["admin"],
         "body": {"id": "no-such-device"}}])
    assert got["history read"]["status"] == 200, got["history read"]
    assert got["history anonymous"]["status"] == 401
    assert got["remove control"]["status"] == 403 and 'scope="admin"' in got["remove control"]["www"]
    assert got["remove admin"]["status"] not in (401, 403), got["remove admin"]


def test_admin_token_writes_the_directory(netns, hub, tokens):
    http = hub.info["http"]
    got = in_ns(netns[0], [
        {"id": "put", "method": "PUT", "url": f"{http}/things/urn:test:x", "token": tokens[1]["admin"],
         "body": _foreign_td(), "content_type": "application/td+json"},
        {"id": "get", "method": "GET", "url": f"{http}/things/urn:test:x", "token": tokens[1]["read"]},
        {"id": "delete", "method": "DELETE", "url": f"{http}/things/urn:test:x", "token": tokens[1]["admin"]},
        # DESIGN.md §8: the hub alone may change its own Things in its directory, admin or not
        {"id": "own", "method": "DELETE", "url": f"{http}/things/{hub.hub_id}", "token": tokens[1]["admin"]},
    ])
    assert got["put"]["status"] == 201, got["put"]
    assert got["get"]["status"] == 200 and json.loads(got["get"]["body"])["id"] == "urn:test:x"
    assert got["delete"]["status"] == 204
    assert got["own"]["status"] == 403 and "www" in got["own"]


def test_every_td_declares_the_bearer_schemes_it_is_served_with(netns, hub, tokens):
    http = hub.info["http"]
    got = in_ns(netns[0], [
        {"id": "all", "method": "GET", "url": f"{http}/wot?expanded=1", "token": tokens[1]["read"]},
        {"id": "dir", "method": "GET", "url": f"{http}/.well-known/wot", "token": tokens[1]["read"]},
        {"id": "listed", "method": "GET", "url": f"{http}/things", "token": tokens[1]["read"]}])
    tds = json.loads(got["all"]["body"])
    assert set(tds) >= {"hub", "pad"}
    # what this hub serves, not the TDs other tests of the module registered (a foreign TD keeps its own)
    listed = [td for td in json.loads(got["listed"]["body"]) if not td["id"].startswith("urn:test:")]
    for td in [*tds.values(), *listed]:
        assert td["security"] == ["bearer_sc"], td["id"]
        assert td["securityDefinitions"]["bearer_sc"]["scheme"] == "bearer"
        assert td["securityDefinitions"]["bearer_sc"]["in"] == "header"
        forms = [f for key in ("properties", "events", "actions") for a in (td.get(key) or {}).values()
                 for f in a["forms"]]
        ws = [f for f in forms if f["href"].startswith("ws")]
        if not td["id"].startswith("urn:wott-hub:"):  # the directory's own TD: HTTP only
            continue
        assert ws and all(f["security"] == ["bearer_either_sc"] for f in ws)
        sse = [f for f in forms if f.get("subprotocol") == "sse"]
        assert sse and all(f["security"] == ["bearer_either_sc"] for f in sse)
        assert td["securityDefinitions"]["bearer_either_sc"] == {
            **td["securityDefinitions"]["bearer_either_sc"], "scheme": "combo",
            "oneOf": ["bearer_sc", "bearer_query_sc"]}
        query = td["securityDefinitions"]["bearer_query_sc"]
        assert (query["scheme"], query["in"], query["name"]) == ("bearer", "query", "access_token")
    directory = json.loads(got["dir"]["body"])
    assert directory["security"] == ["bearer_sc"]


def test_websocket_and_sse_take_the_token_as_a_query_parameter(netns, hub, tokens):
    read = tokens[1]["read"]
    got = in_ns(netns[0], [
        {"id": "ws", "method": "GET", "ws": True, "url": f"{hub.info['websocket']}/hub?access_token={read}",
         "send": {"jsonrpc": "2.0", "id": 1, "method": "read_property", "params": {"name": "devices"}}},
        {"id": "ws invoke", "method": "GET", "ws": True,
         "url": f"{hub.info['websocket']}/hub?access_token={read}",
         "send": {"jsonrpc": "2.0", "id": 2, "method": "invoke_action",
                  "params": {"name": "replay", "parameters": {"device": "pad"}}}},
        {"id": "sse", "method": "GET", "sse": True,
         "url": f"{hub.info['http']}/wot/pad/events?access_token={read}"},
    ])
    assert got["ws"]["status"] == 101 and '"pad"' in got["ws"]["body"]
    assert "invoke_action needs a token with scope control" in got["ws invoke"]["body"]
    assert got["sse"]["status"] == 200 and got["sse"]["body"].startswith("retry: 1000\n")


def test_cors_answers_only_the_configured_origins_off_loopback(netns, hub, tokens):
    url = f"{hub.info['http']}/wot/hub"
    got = in_ns(netns[0], [
        {"id": "ok", "method": "GET", "url": url, "token": tokens[1]["read"], "origin": ORIGIN},
        {"id": "other", "method": "GET", "url": url, "token": tokens[1]["read"], "origin": "http://evil.example"}])
    assert got["ok"]["cors"] == ORIGIN
    assert got["other"]["cors"] is None


def test_audit_trail_and_no_secret_in_logs_or_history(netns, hub, tokens):
    d, made = tokens
    http = hub.info["http"]
    routes = _routes(hub)
    # every request whose audit row is asserted below is made here: the test passes alone or in any order
    _ask(netns[0], {"hub TD": routes["hub TD"]})  # no token: 401
    _ask(netns[0], {"action replay": routes["action replay"]}, token=made["read"])  # 403
    _ask(netns[0], {"action replay": routes["action replay"]}, token=made["control"])  # 200
    td = {**_foreign_td(), "id": "urn:test:audit"}
    in_ns(netns[0], [{"id": "x", "method": "GET", "url": f"{http}/wot/hub?access_token={made['read']}"},
                     {"id": "put", "method": "PUT", "url": f"{http}/things/{td['id']}",
                      "token": made["admin"], "body": td, "content_type": "application/td+json"},
                     {"id": "y", "method": "POST", "url": f"{http}/wot/hub/actions/stopReplay",
                      "token": made["control"], "body": {"thing": "nothing"}}])

    def audited():
        out = subprocess.run([WOTT_HUB, "history", "audit", "--database", str(d / "hub.db"), "--json",
                              "--limit", "1000"], capture_output=True, text=True)
        rows = [json.loads(line) for line in out.stdout.splitlines()]
        return rows if any(r["target"] == "/wot/hub/actions/stopReplay" and r["who"] == "control-client"
                           for r in rows) else None

    rows = wait_for(audited, 60)
    assert any(r["who"] == "-" and r["status"] == 401 and r["address"] == NS_IP for r in rows)
    assert any(r["who"] == "read-client" and r["status"] == 403 and r["action"] == "POST" for r in rows)
    assert any(r["who"] == "admin-client" and r["action"] == "PUT" and r["status"] == 201 for r in rows)
    assert any(r["who"] == "control-client" and r["target"] == "/wot/hub/actions/replay"
               and r["status"] == 200 for r in rows)
    log = hub.log_path.read_text()
    assert "/wot/hub" in log  # the access log is there, without the query
    raw = (d / "hub.db").read_bytes() + log.encode()
    for wal in d.glob("hub.db-*"):
        raw += wal.read_bytes()
    for token in made.values():
        secret = token.split("_", 2)[2]
        assert secret.encode() not in raw
    con = sqlite3.connect(d / "hub.db")
    assert con.execute("select count(*) from audit_log").fetchone()[0] >= len(rows)
    con.close()


def test_tls_serves_https_and_wss_and_refuses_a_client_trusting_another_ca(netns, tokens, tmp_path):
    d, made = tokens
    cert, key = write_selfsigned(tmp_path / "tls", [netns[1]])
    other, _ = write_selfsigned(tmp_path / "other", [netns[1]])
    cfg = write_config(tmp_path, netns[1], f'[security]\ntokens_file = "{d / "tokens.json"}"\n'
                                           f'cert = "{cert}"\nkey = "{key}"')
    hub = HubProcess(["-c", cfg], tmp_path)
    try:
        http, ws = hub.info["http"], hub.info["websocket"]
        assert http.startswith("https://") and ws.startswith("wss://")
        got = in_ns(netns[0], [
            {"id": "td", "method": "GET", "url": f"{http}/wot/pad", "token": made["read"],
             "cafile": str(cert)},
            {"id": "wss", "method": "GET", "ws": True, "url": f"{ws}/pad?access_token={made['read']}",
             "cafile": str(cert)},
            {"id": "sse", "method": "GET", "sse": True, "until": "\ndata: {", "url": f"{http}/wot/pad/events",
             "token": made["read"], "cafile": str(cert)},  # records through tornado's TLS stream
            {"id": "wrong ca", "method": "GET", "url": f"{http}/wot/pad", "token": made["read"],
             "cafile": str(other)},
            {"id": "no token", "method": "GET", "url": f"{http}/wot/pad", "cafile": str(cert)}])
        assert got["td"]["status"] == 200
        td = json.loads(got["td"]["body"])
        hrefs = [f["href"] for a in td["events"].values() for f in a["forms"]]
        assert any(h.startswith("https://") for h in hrefs) and any(h.startswith("wss://") for h in hrefs)
        assert not any(h.startswith(("http://", "ws://")) for h in hrefs)
        assert got["wss"]["status"] == 101
        assert got["sse"]["status"] == 200 and "\ndata: {" in got["sse"]["body"], got["sse"]
        assert "CERTIFICATE_VERIFY_FAILED" in got["wrong ca"]["error"]
        assert got["no token"]["status"] == 401
    finally:
        hub.stop()


def test_a_non_loopback_hub_without_credentials_refuses_to_start_unless_insecure(netns, tmp_path):
    out = subprocess.run([WOTT_HUB, "run", "--host", netns[1], "--port", "0", "--ws-port", "0",
                          "--no-history"], capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1
    assert lines[0].startswith(f"error: refusing to listen on {netns[1]} without credentials")
    assert "wott-hub tokens create" in lines[0] and "--insecure" in lines[0]
    hub = HubProcess(["--host", netns[1], "--port", "0", "--ws-port", "0", "--no-history", "--insecure"],
                     tmp_path)
    try:
        got = in_ns(netns[0], [{"id": "td", "method": "GET", "url": f"{hub.info['http']}/wot/hub"}])
        assert got["td"]["status"] == 200
        assert json.loads(got["td"]["body"])["security"] == ["nosec_sc"]
    finally:
        hub.stop()
