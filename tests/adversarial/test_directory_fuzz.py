"""Property-based fuzzing (hypothesis) of the directory's HTTP API against a real directory server:
random JSONPath queries, random and deep bodies, odd ids and headers. Never a 500, never a hang
(every request has a timeout), every error a problem+json, and afterwards a TD GET answers within a
bound. Bounded ``max_examples`` keep the whole file within a few seconds."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from typing import Any
from urllib.parse import quote

import httpx
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

TOKEN = "fuzz-token"
BOUND_S = 30.0  # "still answers": a hang's bound, not a speed (a loaded machine answers late)
FUZZ = settings(max_examples=50, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])


def make_td(thing_id: str, **extra: Any) -> dict[str, Any]:
    return {"@context": "https://www.w3.org/2022/wot/td/v1.1", "id": thing_id, "title": f"thing {thing_id}",
            "securityDefinitions": {"nosec_sc": {"scheme": "nosec"}}, "security": "nosec_sc", **extra}


@pytest.fixture(scope="module")
def http(directory_thread: Any) -> Iterator[httpx.Client]:
    srv = directory_thread(TOKEN).start()
    assert srv.server is not None
    srv.server.directory.search_engine.time_budget_s = 0.25  # over-budget examples end sooner
    with httpx.Client(base_url=srv.server.url, headers={"Authorization": f"Bearer {TOKEN}"},
                      timeout=10) as client:
        for i in range(20):
            td = make_td(f"urn:fuzz:{i}", description="abc\n" * i, properties={
                f"p{i}": {"type": "number", "minimum": i, "forms": [{"href": f"http://x.example/{i}"}]}})
            assert client.put(f"/things/urn:fuzz:{i}", json=td).status_code == 201
        yield client
        still_answers(client)
    srv.stop()


def still_answers(client: httpx.Client) -> None:
    start = time.monotonic()
    resp = client.get("/things/urn:fuzz:3")
    assert resp.status_code == 200 and resp.json()["id"] == "urn:fuzz:3"
    assert time.monotonic() - start < BOUND_S


def check(resp: httpx.Response, search: bool = False) -> None:
    """No 500; an error is problem+json; only a search may say 503 (over its time budget)."""
    allowed_5xx = {503} if search else set()
    assert resp.status_code < 500 or resp.status_code in allowed_5xx, (resp.status_code, resp.text[:300])
    if resp.status_code >= 400:
        assert resp.headers["Content-Type"].startswith("application/problem+json"), resp.text[:300]
        if resp.request.method != "HEAD":
            assert resp.json()["status"] == resp.status_code


# --- JSONPath queries ------------------------------------------------------------------------------

names = st.sampled_from(["id", "title", "properties", "forms", "href", "type", "minimum", "a", "@type"])
regexes = st.one_of(
    st.sampled_from(["(.|.){24}Q", "(.|.)*Q", "(a*)*b", "^abc$", "\\p{Lu}", "[", "(?P<x>a)", "\\1",
                     "a{1000}{1000}", "x{99999}", ".*", "thing urn:fuzz:1.?"]),
    st.text(alphabet="().|*+?{}[]^$\\aQ0-9,pL", max_size=30))
literals = st.one_of(st.integers(-10, 10).map(str), st.sampled_from(["true", "false", "null", "1.5e300"]),
                     st.text(max_size=10).map(json.dumps))
relative = st.lists(names, min_size=1, max_size=4).map(lambda parts: "@" + "".join(f".{p}" for p in parts))


def expressions() -> st.SearchStrategy[str]:
    base = st.one_of(
        st.tuples(relative, st.sampled_from(["==", "!=", "<", ">="]), literals).map(" ".join),
        st.tuples(st.sampled_from(["search", "match"]), relative, regexes).map(
            lambda t: f"{t[0]}({t[1]}, {json.dumps(t[2])})"),
        relative.map(lambda r: f"length({r}) > 1"),
        relative.map(lambda r: f"count({r}..*) >= 0"),
        relative)
    return st.recursive(base, lambda inner: st.one_of(
        inner.map(lambda e: f"!({e})"),
        st.tuples(inner, st.sampled_from(["&&", "||"]), inner).map(lambda t: f"({t[0]} {t[1]} {t[2]})"),
        st.tuples(relative, inner).map(lambda t: f"{t[0]}[?{t[1]}]")), max_leaves=6)


selectors = st.one_of(
    names.map(lambda n: f".{n}" if n.isalpha() else f"[{json.dumps(n)}]"),
    st.integers(-3, 30).map(lambda i: f"[{i}]"),
    st.sampled_from(["[*]", "..*", ".*", "[::-1]", "[1:5:2]", "[0:0:0]", "..id", "..[0]", "..[?@]"]),
    expressions().map(lambda e: f"[?{e}]"))
queries = st.one_of(
    st.lists(selectors, max_size=12).map(lambda parts: "$" + "".join(parts)),
    st.integers(60, 1500).map(lambda n: "$" + "[0]" * n),
    st.integers(1, 8).map(lambda n: "$" + "..*" * n),
    st.text(max_size=200))


@FUZZ
@given(query=queries)
def test_random_queries_never_fail_or_hang(http: httpx.Client, query: str) -> None:
    check(http.get("/search/jsonpath", params={"query": query}), search=True)


# --- bodies, ids, methods ---------------------------------------------------------------------------

json_values = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(), st.floats(allow_nan=False, allow_infinity=False),
              st.text(max_size=20)),
    lambda inner: st.one_of(st.lists(inner, max_size=4),
                            st.dictionaries(st.text(max_size=8), inner, max_size=4)),
    max_leaves=20)
odd_ids = st.one_of(st.text(min_size=1, max_size=60),
                    st.sampled_from(["urn:fuzz:1", "..", "../../etc/passwd", "urn:x/../y", "%00", " ",
                                     "a\u0000b", "urn:" + "x" * 5000, "\ud800", "http://[::1]/x?y#z"]))


def deep_text(depth: int, opener: str) -> str:
    close = "}" if opener.startswith("{") else "]"
    return opener * depth + ("{}" if close == "}" else "0") + close * depth


bodies = st.one_of(
    json_values.map(json.dumps),
    st.tuples(st.text(max_size=8), json_values).map(
        lambda kv: json.dumps(make_td("urn:fuzz:1", **{kv[0]: kv[1]}))),
    st.tuples(st.integers(1, 3000), st.sampled_from(['{"a":', "["])).map(lambda t: deep_text(*t)),
    st.integers(50, 400).map(lambda e: json.dumps(make_td("urn:fuzz:1", registration={"ttl": 0}))
                             .replace('"ttl": 0', f'"ttl": 1e{e}')),
    st.binary(max_size=60).map(lambda b: b.decode("latin-1")),
    st.just(""))
content_types = st.sampled_from(["application/td+json", "application/json", "application/merge-patch+json",
                                 "application/ld+json; charset=utf-8", "text/plain", "",
                                 "application/td+json;;"])


@FUZZ
@given(method=st.sampled_from(["PUT", "PATCH", "POST", "DELETE", "GET", "HEAD"]), thing_id=odd_ids,
       body=bodies, content_type=content_types)
def test_random_writes_never_fail_or_hang(http: httpx.Client, method: str, thing_id: str, body: str,
                                          content_type: str) -> None:
    path = "/things" if method == "POST" else f"/things/{quote(thing_id, safe='', errors='surrogatepass')}"
    headers = {"Content-Type": content_type} if content_type else {}
    content = body.encode("utf-8", "surrogatepass") if method in ("PUT", "PATCH", "POST") else None
    check(http.request(method, path, content=content, headers=headers))
    if method in ("PUT", "PATCH", "DELETE"):
        http.put("/things/urn:fuzz:1", json=make_td("urn:fuzz:1"))  # keep a TD the queries can find


# --- headers ----------------------------------------------------------------------------------------

# field-content of RFC 9110 (visible ASCII, space, obs-text); with control characters tornado's
# HTTP/1 layer refuses the request before any handler runs (a bare 400, no body to check)
latin1 = st.text(alphabet=st.one_of(st.characters(min_codepoint=32, max_codepoint=126),
                                    st.characters(min_codepoint=160, max_codepoint=255)), max_size=80)


@settings(FUZZ, max_examples=30)
@given(path=st.sampled_from(["/things", "/things/urn:fuzz:2", "/events", "/events/thing_created",
                             "/search/jsonpath?query=$..id", "/.well-known/wot", "/events/nope"]),
       method=st.sampled_from(["HEAD", "OPTIONS", "GET"]), authorization=latin1, last_event_id=latin1,
       accept=latin1, extra=st.dictionaries(st.from_regex(r"\AX-[A-Za-z]{1,12}\Z"), latin1, max_size=3))
def test_random_headers_never_fail_or_hang(http: httpx.Client, path: str, method: str, authorization: str,
                                           last_event_id: str, accept: str, extra: dict[str, str]) -> None:
    if method == "GET" and path.startswith("/events"):
        method = "HEAD"  # a GET would stream for ever
    given = {"Authorization": authorization, "Last-Event-ID": last_event_id, "Accept": accept, **extra}
    headers = {name: value.strip(" ").encode("latin-1") for name, value in given.items()}  # h11 wants so
    check(http.request(method, path, headers=headers), search=path.startswith("/search"))
    still_answers(http)
