"""The directory's own TD declares exactly what its server enforces, form by form (issue 17).

For every form of the TD at ``/.well-known/wot`` a request is made without
credentials and with them: a form whose security is ``nosec`` is admitted
without, one declaring ``bearer`` answers 401 with ``WWW-Authenticate`` without
and is admitted with the token (``bearer_either_sc``: also as ``?access_token=``).
Three servers: the hub's embedded directory with tokens (from another network
namespace, the hub's scoped bearer scheme), an open hub on loopback (``nosec``
only), and a standalone ``wott_directory`` with each of its token settings.
No scheme is defined that no form uses.
"""

from __future__ import annotations

import asyncio
import json
import threading
from collections.abc import Callable
from urllib.parse import urljoin

import pytest

from .conftest import in_ns
from .nsclient import http_request
from .test_network import _foreign_td, hub, tokens  # noqa: F401  # the protected hub of test_network

NEW_ID = "urn:test:dirtd"

Send = Callable[[list[dict]], dict]


def _local(reqs: list[dict]) -> dict:
    return {r["id"]: http_request(r) for r in reqs}


def _schemes(td: dict, names: list[str]) -> set[str]:
    """The schemes ``names`` stand for (a combo: its members')."""
    out: set[str] = set()
    for name in names:
        d = td["securityDefinitions"][name]
        out |= _schemes(td, d["oneOf"]) if d["scheme"] == "combo" else {d["scheme"]}
    return out


def _requests(td: dict, existing: str) -> list[dict]:
    """One request per form of the TD (the ``things`` property's template form), writes in order."""
    out = []
    for kind in ("properties", "actions", "events"):
        for name, aff in td[kind].items():
            form = aff["forms"][-1]
            href = (form["href"].replace("{?offset,limit,format}", "").replace("{?diff}", "")
                    .replace("{query}", "$").replace("{id}", NEW_ID if name != "retrieveThing" else existing))
            r = {"id": name, "method": form.get("htv:methodName", "GET"), "url": urljoin(td["base"], href),
                 "security": form.get("security", td["security"]), "sse": kind == "events"}
            if name in ("createThing", "updateThing", "createAnonymousThing"):
                r["body"] = {**_foreign_td(), "id": NEW_ID, "title": name}
                if name == "createAnonymousThing":
                    del r["body"]["id"]
            elif name == "partiallyUpdateThing":
                r["body"], r["content_type"] = {"title": "patched"}, "application/merge-patch+json"
            out.append(r)
    return out


def _check(td: dict, send: Send, existing: str, token_for: Callable[[dict], str | None]) -> None:
    """Every form: without credentials as declared; with the token it names admitted."""
    reqs = _requests(td, existing)
    assert {r["id"] for r in reqs} >= {"things", "retrieveThing", "searchJSONPath", "thingCreated"}
    bare = send([{k: v for k, v in r.items() if k != "security"} for r in reqs])
    for r in reqs:
        got, schemes = bare[r["id"]], _schemes(td, r["security"])
        assert schemes in ({"nosec"}, {"bearer"}), (r["id"], schemes)
        if schemes == {"nosec"}:
            assert got["status"] < 400, (r["id"], got)
        else:
            assert got["status"] == 401 and got["www"].startswith("Bearer"), (r["id"], got)
    authed = [{**r, "token": token_for(r)} for r in reqs if _schemes(td, r["security"]) == {"bearer"}]
    query = [{**r, "id": f"{r['id']} (query)", "token": None,
              "url": f"{r['url']}{'&' if '?' in r['url'] else '?'}access_token={token_for(r)}"}
             for r in reqs if "bearer_either_sc" in r["security"]]
    got = send([{k: v for k, v in r.items() if k != "security"} for r in authed + query])
    for r in authed + query:
        assert got[r["id"]]["status"] < 400, (r["id"], got[r["id"]])
    used = {s for r in reqs for s in r["security"]} | set(td["security"])
    used |= {m for s in list(used) for m in td["securityDefinitions"][s].get("oneOf", ())}
    assert set(td["securityDefinitions"]) == used, "a scheme no form uses is defined"


def test_the_embedded_directory_of_a_protected_hub_declares_and_enforces_the_hubs_bearer_scheme(
        netns, hub, tokens):  # noqa: F811
    made = tokens[1]
    http = hub.info["http"]
    got = in_ns(netns[0], [
        {"id": "dir", "method": "GET", "url": f"{http}/.well-known/wot", "token": made["read"]},
        {"id": "hub", "method": "GET", "url": f"{http}/wot/hub", "token": made["read"]}])
    td, hub_td = json.loads(got["dir"]["body"]), json.loads(got["hub"]["body"])
    assert "nosec_sc" not in td["securityDefinitions"] and td["security"] == ["bearer_sc"]
    assert td["securityDefinitions"] == hub_td["securityDefinitions"]  # the hub's scheme, its scopes
    assert "static" not in json.dumps(td["securityDefinitions"])
    writes = {"createThing", "createAnonymousThing", "updateThing", "partiallyUpdateThing", "deleteThing"}
    _check(td, lambda reqs: in_ns(netns[0], reqs), hub.hub_id,
           lambda r: made["admin"] if r["id"] in writes else made["read"])
    # the scope: a read token may read the directory, not write it
    refused = in_ns(netns[0], [{"id": "w", "method": "PUT", "url": f"{http}/things/{NEW_ID}",
                                "token": made["read"], "body": _foreign_td()}])["w"]
    assert refused["status"] == 403 and 'scope="admin"' in refused["www"]


def test_the_embedded_directory_of_an_open_hub_declares_nosec_only(tmp_path, hub_thread):
    from wott_hub.config import HubConfig

    ht = hub_thread(HubConfig(http_port=0, ws_port=0, database=str(tmp_path / "hub.db"))).start()
    try:
        td = _local([{"id": "td", "method": "GET", "url": f"{ht.url}/.well-known/wot"}])["td"]
        td = json.loads(td["body"])
        assert td["securityDefinitions"] == {"nosec_sc": {"scheme": "nosec"}}
        assert td["security"] == ["nosec_sc"]
        _check(td, _local, ht.hub._identity.hub_thing_id, lambda r: None)
    finally:
        ht.stop()


class _Standalone:
    """A ``wott_directory`` server on 127.0.0.1 in its own thread."""

    def __init__(self, **settings) -> None:
        from wott_directory import Directory, DirectoryServer, DirectorySettings

        self._ready, self.server = threading.Event(), None

        async def main() -> None:
            self._stop = asyncio.Event()
            self.server = await DirectoryServer(Directory(DirectorySettings(**settings))).start()
            self._ready.set()
            await self._stop.wait()
            await self.server.stop()

        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_until_complete, args=(main(),), daemon=True)
        self.thread.start()
        assert self._ready.wait(20), "the directory did not start"

    def stop(self) -> None:
        self.loop.call_soon_threadsafe(self._stop.set)
        self.thread.join(20)


@pytest.mark.parametrize(("settings", "schemes"), [
    ({"token": "s3cret"}, {"nosec_sc", "bearer_sc"}),  # reads open, writes with the token
    ({"token": "s3cret", "protect_reads": True}, {"bearer_sc"}),
    ({"open_writes": True}, {"nosec_sc"}),
    ({}, {"nosec_sc"}),  # no token, not open: read-only, no write action declared
])
def test_a_standalone_directory_declares_what_its_token_settings_enforce(settings, schemes):
    srv = _Standalone(**settings)
    try:
        url = srv.server.url
        td = json.loads(_local([{"id": "td", "method": "GET", "url": f"{url}.well-known/wot"}])["td"]["body"])
        assert set(td["securityDefinitions"]) == schemes
        if "bearer_sc" in schemes:
            assert "static" not in td["securityDefinitions"]["bearer_sc"]["description"]
        if not settings:
            assert "createThing" not in td["actions"] and "deleteThing" not in td["actions"]
            put = _local([{"id": "w", "method": "PUT", "url": f"{url}things/{NEW_ID}",
                           "body": {**_foreign_td(), "id": NEW_ID}}])
            assert put["w"]["status"] == 403  # not declared, and indeed refused
        _check(td, _local, td["id"], lambda r: settings.get("token"))
    finally:
        srv.stop()
