"""Every answer has the media type the directory's own TD declares for it.

The test walks the TD served at ``/.well-known/wot``: each form of each affordance, and for each
form its ``response`` and every ``additionalResponses`` entry. A request that gets that response
(``REQUESTS``: what to send for it) is made as the form says (method, href template, the form's
``contentType`` for a body) and the answer's status and ``Content-Type`` must be the declared ones.
A response the TD declares without a request here fails the test, so a new one cannot go unchecked.
node-wot 0.9.2 checks an action's answer against the declared type and threw, after the write had
succeeded, on tornado's ``text/html`` (201) or on no type at all (204).
"""

from __future__ import annotations

import json
import re
import uuid
from collections.abc import Callable
from typing import Any
from urllib.parse import quote, urljoin

import httpx
import pytest

Setup = Callable[[httpx.Client, Any], tuple[dict[str, str], Any]]
"""(client, helpers) -> (the form's URI variables, the request body or None)."""


def _new(http: httpx.Client, helpers: Any, *, anonymous: bool = False) -> str:
    """An id no TD has yet."""
    return "" if anonymous else f"urn:example:{uuid.uuid4()}"


def _existing(http: httpx.Client, helpers: Any) -> str:
    thing_id = _new(http, helpers)
    r = http.put(f"/things/{quote(thing_id)}", json=helpers.make_td(thing_id), headers=helpers.td_headers())
    assert r.status_code == 201, r.text
    return thing_id


INVALID_TD = {"title": 42}  # not a TD: no @context, a title that is not a string

REQUESTS: dict[tuple[str, int], Setup] = {
    ("things", 200): lambda c, h: ({}, None),
    ("things", 400): lambda c, h: ({"limit": "0"}, None),
    ("createThing", 201): lambda c, h: ({"id": (i := _new(c, h))}, h.make_td(i)),
    ("createThing", 400): lambda c, h: ({"id": _new(c, h)}, INVALID_TD),
    ("createAnonymousThing", 201): lambda c, h: ({}, h.make_td(None)),
    ("createAnonymousThing", 400): lambda c, h: ({}, INVALID_TD),
    ("retrieveThing", 200): lambda c, h: ({"id": _existing(c, h)}, None),
    ("retrieveThing", 404): lambda c, h: ({"id": _new(c, h)}, None),
    ("updateThing", 204): lambda c, h: ({"id": (i := _existing(c, h))}, h.make_td(i, title="updated")),
    ("updateThing", 400): lambda c, h: ({"id": _existing(c, h)}, INVALID_TD),
    ("partiallyUpdateThing", 204): lambda c, h: ({"id": _existing(c, h)}, {"title": "patched"}),
    ("partiallyUpdateThing", 400): lambda c, h: ({"id": _existing(c, h)}, {"title": 42}),
    ("partiallyUpdateThing", 404): lambda c, h: ({"id": _new(c, h)}, {"title": "patched"}),
    ("deleteThing", 204): lambda c, h: ({"id": _existing(c, h)}, None),
    ("deleteThing", 404): lambda c, h: ({"id": _new(c, h)}, None),
    ("searchJSONPath", 200): lambda c, h: ({"query": "$[*].id"}, None),
    ("searchJSONPath", 400): lambda c, h: ({"query": "$[?(@.title ==="}, None),
    ("thingCreated", 200): lambda c, h: ({}, None),
    ("thingUpdated", 200): lambda c, h: ({"diff": "true"}, None),
    ("thingDeleted", 200): lambda c, h: ({}, None),
}


def expand(template: str, variables: dict[str, str]) -> str:
    """RFC 6570 as the directory's TD uses it: ``{id}`` (simple) and ``{?a,b}`` (form-style query).
    Variables the template does not name go in the query (the plain ``things`` form wotpy takes)."""
    left = dict(variables)

    def one(m: re.Match[str]) -> str:
        expr = m.group(1)
        if expr.startswith("?"):
            pairs = [(n, left.pop(n)) for n in expr[1:].split(",") if n in left]
            return ("?" + "&".join(f"{n}={quote(v, safe='')}" for n, v in pairs)) if pairs else ""
        return quote(left.pop(expr), safe="")

    out = re.sub(r"\{([^}]+)\}", one, template)
    if left:
        out += ("&" if "?" in out else "?") + "&".join(f"{n}={quote(v, safe='')}" for n, v in left.items())
    return out


def _media(value: str | None) -> str | None:
    return value.split(";", 1)[0].strip() if value else None


def _declared(td: dict[str, Any]) -> list[tuple[str, str, dict[str, Any], int, str]]:
    """(kind, affordance, form, status, content type) for every response the TD declares."""
    out = []
    for kind in ("properties", "actions", "events"):
        for name, aff in td.get(kind, {}).items():
            for form in aff["forms"]:
                response = form.get("response", {})
                ok = response.get("htv:statusCodeValue", 200)
                out.append((kind, name, form, ok, response.get("contentType", form.get("contentType"))))
                for extra in form.get("additionalResponses", []):
                    out.append((kind, name, form, extra["htv:statusCodeValue"], extra["contentType"]))
    return out


def test_every_answer_has_the_content_type_the_directory_td_declares(tdd, http, helpers):
    td = http.get("/.well-known/wot").json()
    assert _media(http.get("/.well-known/wot").headers["content-type"]) == "application/td+json"
    declared = _declared(td)
    names = {name for _, name, *_ in declared}
    assert {"things", "createThing", "updateThing", "partiallyUpdateThing", "deleteThing",
            "retrieveThing", "thingCreated"} <= names  # the write actions too: this directory has a token
    missing = {(name, status) for _, name, _, status, _ in declared} - set(REQUESTS)
    assert not missing, f"responses the TD declares that this test does not request: {missing}"
    checked = []
    for kind, name, form, status, content_type in declared:
        variables, body = REQUESTS[(name, status)](http, helpers)
        url = urljoin(td["base"], expand(form["href"], variables))
        method = form.get("htv:methodName", "GET")
        headers = {}
        content = None
        if body is not None:
            headers["Content-Type"] = form["contentType"]
            content = json.dumps(body).encode()
        if kind == "events":
            headers["Accept"] = "text/event-stream"
            with http.stream(method, url, headers=headers) as r:
                got = (r.status_code, _media(r.headers.get("content-type")))
        else:
            r = http.request(method, url, headers=headers, content=content)
            got = (r.status_code, _media(r.headers.get("content-type")))
        assert got == (status, content_type), (name, form["href"], method, r.text[:300])
        checked.append((name, status))
    assert len(checked) == len(declared) >= 15


@pytest.mark.parametrize("status", [201, 204])
def test_an_empty_answer_says_text_plain(http, helpers, status):
    thing_id = "urn:example:lamp"
    if status == 204:
        http.put(f"/things/{thing_id}", json=helpers.make_td(thing_id), headers=helpers.td_headers())
    r = http.put(f"/things/{thing_id}", json=helpers.make_td(thing_id), headers=helpers.td_headers())
    assert r.status_code == status and r.content == b""
    assert r.headers["content-type"] == "text/plain"
    preflight = http.options(f"/things/{thing_id}")  # other 204s (no TD response) keep no type
    assert preflight.status_code == 204 and "content-type" not in preflight.headers


def test_event_streams_begin_with_a_retry_field(tdd, http, helpers):
    # not a comment line, which older clients took for an empty message; no blank line after it, so
    # that it belongs to the first event (httpx-sse hands on any block with a retry: as a message)
    with httpx.Client(base_url=tdd.url, timeout=10) as c, c.stream(
            "GET", "/events", headers={"Accept": "text/event-stream"}) as r:
        chunks = r.iter_raw()
        first = next(chunks)
        assert first == b"retry: 1000\n", first
        http.put("/things/urn:example:lamp", json=helpers.make_td(), headers=helpers.td_headers())
        rest = next(chunks)
    assert re.fullmatch(rb"id: \d+\nevent: thing_created\ndata: .*\n\n", rest, re.S), rest
