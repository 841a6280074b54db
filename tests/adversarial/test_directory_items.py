"""Issue 16, the directory's items, each against a real directory (or a real hub) on 127.0.0.1:
search with bounded cost (1), the hub's own Things only the hub changes (5), deep TDs and paths (6),
CORS, OPTIONS, unknown paths and absurd ttls (10)."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from datetime import UTC, datetime
from typing import Any

import httpx
import pytest
from sqlalchemy import create_engine
from wott_directory.models import ThingRow
from wott_directory.validation import MAX_TD_DEPTH, MAX_TTL_S

TOKEN = "adversarial-token"
PROBLEM = "application/problem+json"
TD_TYPE = {"Content-Type": "application/td+json"}
MERGE_PATCH = {"Content-Type": "application/merge-patch+json"}
BOUND_S = 30.0
"""What "answers" means here: a hang's bound, not a speed (a loaded machine answers late; a search
that backtracks exponentially hits its 2 s budget and answers 503, which the tests tell apart)."""


@pytest.fixture
def tdd(directory_thread: Any) -> Iterator[Any]:
    srv = directory_thread(TOKEN).start()
    yield srv
    srv.stop()


@pytest.fixture
def http(tdd: Any) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=tdd.url, headers={"Authorization": f"Bearer {TOKEN}"}, timeout=30) as c:
        yield c


def make_td(thing_id: str, **extra: Any) -> dict[str, Any]:
    return {"@context": "https://www.w3.org/2022/wot/td/v1.1", "id": thing_id, "title": f"thing {thing_id}",
            "securityDefinitions": {"nosec_sc": {"scheme": "nosec"}}, "security": "nosec_sc", **extra}


def nested(depth: int) -> dict[str, Any]:
    """An object ``depth`` levels deep: {"a": {"a": ... {}}}."""
    doc: dict[str, Any] = {}
    for _ in range(depth - 1):
        doc = {"a": doc}
    return doc


def assert_problem(resp: httpx.Response, status: int, *words: str) -> dict[str, Any]:
    assert resp.status_code == status, resp.text
    assert resp.headers["Content-Type"].startswith(PROBLEM)
    body = resp.json()
    assert body["status"] == status
    for word in words:
        assert word in body["detail"] + json.dumps(body.get("validationErrors", [])), body
    return body


def timed_get(client: httpx.Client, path: str, **kw: Any) -> tuple[httpx.Response, float]:
    start = time.monotonic()
    resp = client.get(path, **kw)
    return resp, time.monotonic() - start


# --- item 1: search with bounded cost ---------------------------------------------------------------

def test_catastrophic_regexes_answer_at_once_and_budgets_are_named(http: httpx.Client) -> None:
    for i in range(50):
        assert http.put(f"/things/urn:ex:{i}", json=make_td(f"urn:ex:{i}", title="a" * 40)).status_code == 201
    # exponential with backtracking (issue: 5-8 s, doubling per repetition; the second never ends)
    for query in ('$[?search(@.title, "(.|.){24}Q")].id', '$[?search(@.title, "(.|.)*Q")].id',
                  '$[?match(@.title, "(a|a)*(a|a)*(a|a)*Q")].id'):
        resp, took = timed_get(http, "/search/jsonpath", params={"query": query})
        assert resp.status_code == 200 and resp.json() == [] and took < BOUND_S, (query, took)
    # I-Regexp semantics kept: "." is any character but \n and \r; match() is anchored
    resp = http.get("/search/jsonpath", params={"query": '$[?match(@.title, "a.{38}a")].id'})
    assert len(resp.json()) == 50
    assert http.get("/search/jsonpath", params={"query": '$[?match(@.title, "a")].id'}).json() == []

    assert_problem(http.get("/search/jsonpath", params={"query": "$" + "[0]" * 1300}), 400, "max_segments")
    assert_problem(http.get("/search/jsonpath", params={"query": "$" + '["x"]' * 2000}), 400,
                   "max_query_length")
    too_nested = "$" + "[?@" * 10 + "]" * 10
    assert_problem(http.get("/search/jsonpath", params={"query": too_nested}), 400, "max_filter_nesting")


def test_an_over_budget_query_gets_503_and_never_holds_other_clients_up(http: httpx.Client) -> None:
    deep = {"a": [{"b": [{"c": list(range(20))} for _ in range(5)]} for _ in range(5)]}
    for i in range(40):
        assert http.put(f"/things/urn:ex:{i}", json=make_td(f"urn:ex:{i}", x=deep)).status_code == 201
    bomb = "$" + "..*" * 8  # each descendant segment multiplies the nodes: far past any budget
    with ThreadPoolExecutor(1) as pool:
        started = time.monotonic()
        pending = pool.submit(http.get, "/search/jsonpath", params={"query": bomb})
        time.sleep(0.3)
        gets = []
        while not pending.done():  # TD reads while the bomb is evaluated
            resp, took = timed_get(http, "/things/urn:ex:7")
            assert resp.status_code == 200
            gets.append(took)
            time.sleep(0.1)
        bombed = pending.result()
        took_bomb = time.monotonic() - started
    body = assert_problem(bombed, 503, "time_budget_s")
    assert bombed.headers["Retry-After"] and bombed.headers["Access-Control-Allow-Origin"] == "*"
    assert body["instance"] == "/search/jsonpath"
    assert took_bomb < 2.0 + BOUND_S, took_bomb  # the budget (2 s) and the answer bound, no more
    # other clients were answered while it ran: on the loop, one read would wait for all of it
    assert len(gets) >= 2 and max(gets) < BOUND_S, gets
    # the search thread is free again at once
    resp, took = timed_get(http, "/search/jsonpath", params={"query": '$[?@.id=="urn:ex:3"].title'})
    assert resp.json() == ["thing urn:ex:3"] and took < BOUND_S


# --- item 6: deep TDs and long paths -------------------------------------------------------------

def test_deep_tds_are_refused_at_registration_and_deep_patches_too(http: httpx.Client) -> None:
    ok = make_td("urn:ex:ok", x=nested(MAX_TD_DEPTH - 1))
    assert http.put("/things/urn:ex:ok", json=ok).status_code == 201
    for depth in (100, 400, 5000):  # as text: the client's own encoder stops near 1,000 levels
        deep = '{"a":' * (depth - 1) + "{}" + "}" * (depth - 1)
        td_text = json.dumps(make_td("urn:ex:deep", x="X")).replace('"X"', deep)
        assert_problem(http.put("/things/urn:ex:deep", content=td_text, headers=TD_TYPE), 400,
                       f"{MAX_TD_DEPTH} levels")
        assert_problem(http.post("/things", content=td_text.replace('"id": "urn:ex:deep", ', ""),
                                 headers=TD_TYPE), 400, str(MAX_TD_DEPTH))
        assert_problem(http.patch("/things/urn:ex:ok", content='{"x": ' + deep + "}",
                                  headers=MERGE_PATCH), 400,
                       str(MAX_TD_DEPTH))
    resp = http.get("/search/jsonpath", params={"query": "$..a"})
    assert resp.status_code == 200 and len(resp.json()) == MAX_TD_DEPTH - 2
    assert http.get("/search/jsonpath", params={"query": "$..*"}).status_code == 200
    assert_problem(http.get("/search/jsonpath", params={"query": "$" + "[0]" * 1300}), 400, "segments")


def test_a_deep_td_stored_before_the_limit_breaks_no_search_and_can_be_repaired(tmp_path,
                                                                                  directory_thread) -> None:
    db = f"sqlite:///{tmp_path / 'tdd.db'}"
    first = directory_thread(TOKEN, db).start()
    with httpx.Client(base_url=first.url, headers={"Authorization": f"Bearer {TOKEN}"}, timeout=30) as c:
        assert c.put("/things/urn:ex:fine", json=make_td("urn:ex:fine")).status_code == 201
    first.stop()
    now = datetime.now(UTC)  # what an older directory (no depth limit) may have stored
    old = make_td("urn:ex:old", x=nested(400), registration={"created": "2026-01-01T00:00:00.000Z",
                                                              "modified": "2026-01-01T00:00:00.000Z"})
    with create_engine(db).begin() as conn:
        conn.execute(ThingRow.__table__.insert(), [{"id": "urn:ex:old", "td": json.dumps(old),
                                                    "anonymous": False, "own": False, "created": now,
                                                    "modified": now}])
    second = directory_thread(TOKEN, db).start()
    try:
        with httpx.Client(base_url=second.url, headers={"Authorization": f"Bearer {TOKEN}"}, timeout=30) as c:
            for query in ("$..title", "$..*", "$..a", '$[?@.x].id'):
                resp = c.get("/search/jsonpath", params={"query": query})
                assert resp.status_code == 200, (query, resp.text)
            assert "thing urn:ex:fine" in c.get("/search/jsonpath", params={"query": "$..title"}).json()
            assert c.get("/things/urn:ex:old").status_code == 200  # still readable by id
            patch = {"headers": {"Content-Type": "application/merge-patch+json"}}
            assert_problem(c.patch("/things/urn:ex:old", json={"title": "still deep"}, **patch), 400,
                           str(MAX_TD_DEPTH))
            assert c.patch("/things/urn:ex:old", json={"x": None}, **patch).status_code == 204  # repaired
            assert c.get("/search/jsonpath", params={"query": '$[?@.id=="urn:ex:old"].id'}).json() == \
                ["urn:ex:old"]
    finally:
        second.stop()


# --- item 5: the hub's own Things only the hub changes -------------------------------------------

def test_nobody_but_the_hub_changes_or_deletes_the_hubs_things(hub_thread, press_scene) -> None:
    from wott_hub.config import HubConfig
    from wott_hub.network import DirectoryConfig

    for directory in (DirectoryConfig(), DirectoryConfig(token=TOKEN)):  # open loopback; token holder
        ht = hub_thread(HubConfig(name="lab", http_port=0, ws_port=0, history=False,
                                  devices=(press_scene("pad"),), directory=directory)).start()
        try:
            ht.call(ht.hub.sync_directories)
            headers = {"Authorization": f"Bearer {TOKEN}"}
            with httpx.Client(base_url=ht.url, headers=headers, timeout=30) as c:
                ids = ht.hub._identity
                for tid in (ids.device_id("pad"), ids.hub_thing_id):
                    before = c.get(f"/things/{tid}").json()
                    hijacked = {k: v for k, v in before.items() if k != "registration"}
                    hijacked["base"] = "http://attacker.example/"
                    assert_problem(c.put(f"/things/{tid}", json=hijacked), 403, tid, "hub")
                    assert_problem(c.patch(f"/things/{tid}", json={"base": "http://attacker.example/"},
                                           headers=MERGE_PATCH), 403, tid)
                    assert_problem(c.delete(f"/things/{tid}"), 403, tid)
                    after = c.get(f"/things/{tid}").json()
                    assert after.get("base") == before.get("base") and after["title"] == before["title"]
                # others' TDs stay writable, and the hub itself still changes its own
                assert c.put("/things/urn:ex:lamp", json=make_td("urn:ex:lamp")).status_code == 201
                assert c.delete("/things/urn:ex:lamp").status_code == 204
                ht.call(ht.hub.remove_device, "pad")
                ht.call(ht.hub.sync_directories)
                assert c.get(f"/things/{ids.device_id('pad')}").status_code == 404
        finally:
            ht.stop()


# --- item 10: CORS, OPTIONS, unknown paths, absurd ttl -------------------------------------------

def test_cors_options_unknown_paths_and_ttl(http: httpx.Client, tdd: Any) -> None:
    assert http.put("/things/urn:ex:lamp", json=make_td("urn:ex:lamp")).status_code == 201
    with httpx.Client(base_url=tdd.url, timeout=30) as anon:
        for path in ("/things", "/things/urn:ex:lamp", "/search/jsonpath?query=$..id", "/.well-known/wot",
                     "/things/urn:ex:nothing"):
            assert anon.get(path).headers.get("Access-Control-Allow-Origin") == "*", path
        for path, methods in (("/things", "POST"), ("/things/urn:ex:lamp", "PATCH"),
                              ("/search/jsonpath", "GET"), ("/events", "GET")):
            resp = anon.options(path, headers={"Origin": "http://ui.example",
                                               "Access-Control-Request-Method": methods})
            assert resp.status_code == 204, (path, resp.text)
            assert methods in resp.headers["Access-Control-Allow-Methods"]
            assert "Authorization" in resp.headers["Access-Control-Allow-Headers"]
            assert resp.headers["Access-Control-Allow-Origin"] == "*"
        for path in ("/things/", "/search/", "/search/jsonpath/x", "/events/a/b", "/no/such/path"):
            assert_problem(anon.get(path), 404, "No resource")
    for ttl in (1e20, 1e300, MAX_TTL_S + 1, -5):
        assert_problem(http.put("/things/urn:ex:t", json=make_td("urn:ex:t", registration={"ttl": ttl})), 400,
                       "$.registration.ttl")
    body = json.dumps(make_td("urn:ex:t", registration={"ttl": 1})).replace('"ttl": 1', '"ttl": 1e400')
    assert_problem(http.put("/things/urn:ex:t", content=body, headers=TD_TYPE), 400, "1e400")
    far = "9999-12-31T23:59:59-23:59"  # past year 9999 in UTC
    assert_problem(http.put("/things/urn:ex:t", json=make_td("urn:ex:t", registration={"expires": far})), 400,
                   "registration.expires")
    longest = make_td("urn:ex:t", registration={"ttl": MAX_TTL_S})
    assert http.put("/things/urn:ex:t", json=longest).status_code == 201
