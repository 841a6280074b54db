"""Bad requests: each is answered with the right status and an RFC 7807 problem, and the store
is left exactly as it was (same TDs, same collection etag)."""

from __future__ import annotations

import httpx
import pytest


@pytest.fixture
def unchanged(tdd, http, helpers):
    """Assert the collection did not change during the test."""
    http.put("/things/urn:example:lamp", json=helpers.make_td(), headers=helpers.td_headers())
    before = (tdd.call(lambda: tdd.directory.etag), http.get("/things").json())
    yield
    etag, things = tdd.call(lambda: tdd.directory.etag), http.get("/things").json()
    assert etag == before[0]
    strip = [{**td, "registration": {k: v for k, v in td["registration"].items() if k != "retrieved"}}
             for td in things]
    old = [{**td, "registration": {k: v for k, v in td["registration"].items() if k != "retrieved"}}
           for td in before[1]]
    assert strip == old


def assert_problem(r: httpx.Response, status: int) -> dict:
    # tdd-http-error-response, tdd-http-error-response-utf-8
    assert r.status_code == status, r.text
    assert r.headers["content-type"] == "application/problem+json"
    problem = r.json()
    assert problem["status"] == status
    assert problem["title"]
    r.content.decode("utf-8")
    return problem


def test_invalid_json(http, unchanged):
    for body in (b"{", b"{'a': 1}", b"", b"\xff\xfe", b'{"title": NaN}'):
        assert_problem(http.put("/things/urn:example:x", content=body,
                                headers={"Content-Type": "application/td+json"}), 400)
    assert_problem(http.post("/things", content=b"[1,", headers={"Content-Type": "application/td+json"}), 400)


def test_td_failing_the_schema(http, helpers, unchanged):
    # tdd-validation-syntactic, tdd-validation-jsonschema, tdd-validation-result, tdd-validation-response
    td = helpers.make_td("urn:example:bad", title=7)
    del td["securityDefinitions"]
    td["properties"]["status"]["forms"] = [{"op": "readproperty"}]
    td["registration"] = {"ttl": "soon"}
    problem = assert_problem(http.put("/things/urn:example:bad", json=td, headers=helpers.td_headers()), 400)
    errors = problem["validationErrors"]
    assert all(set(e) == {"field", "description"} for e in errors)
    fields = {e["field"] for e in errors}
    assert {"$.title", "$.securityDefinitions", "$.properties.status.forms[0].href",
            "$.registration.ttl"} <= fields, fields


def test_id_must_be_an_absolute_uri(http, helpers, unchanged):
    problem = assert_problem(http.put("/things/not-a-uri", json=helpers.make_td("not-a-uri"),
                                      headers=helpers.td_headers()), 400)
    assert problem["validationErrors"] == [
        {"field": "$.id", "description": "'not-a-uri' is not an absolute URI"}]


def test_not_a_json_object(http, helpers, unchanged):
    problem = assert_problem(http.post("/things", json=["a"], headers=helpers.td_headers()), 400)
    assert problem["validationErrors"][0]["field"] == "$"


def test_problem_details_are_utf8(http, helpers, unchanged):
    # tdd-validation-response-utf-8
    td = helpers.make_td("urn:example:äpfel", title=["Äpfel"])
    r = http.put("/things/urn:example:%C3%A4pfel", json=td, headers=helpers.td_headers())
    problem = assert_problem(r, 400)
    assert "Äpfel" in r.content.decode("utf-8")
    assert problem["instance"].startswith("/things/")


def test_huge_body_with_content_length(tdd, http, helpers, unchanged):
    limit = tdd.directory.settings.max_body_bytes
    body = b'{"title": "' + b"x" * (limit + 10) + b'"}'
    assert_problem(http.put("/things/urn:example:big", content=body, headers=helpers.td_headers()), 413)
    # the connection stays usable for the next request
    assert http.get("/things/urn:example:lamp").status_code == 200


def test_huge_chunked_body(tdd, http, helpers, unchanged):
    limit = tdd.directory.settings.max_body_bytes

    def chunks():
        yield b'{"title": "'
        for _ in range(limit // 65536 + 2):
            yield b"x" * 65536
        yield b'"}'

    r = http.post("/things", content=chunks(), headers=helpers.td_headers())
    assert_problem(r, 413)


def test_malformed_jsonpath(http, unchanged):
    for query in ('$[?@.title=="a"', "title", " $.x", "$.x | $.y", "$[?foo(@)]", "$..[", "$" + "[0]" * 3000):
        problem = assert_problem(http.get("/search/jsonpath", params={"query": query}), 400)
        assert problem["detail"]
    assert_problem(http.get("/search/jsonpath"), 400)
    assert_problem(http.get("/search/jsonpath", params={"query": ""}), 400)


def test_unknown_id(http, unchanged):
    for method in ("GET", "HEAD", "DELETE"):
        r = http.request(method, "/things/urn:example:nothing")
        assert r.status_code == 404
    assert_problem(http.get("/things/urn:example:nothing"), 404)
    assert_problem(http.patch("/things/urn:example:nothing", json={"title": "x"},
                              headers={"Content-Type": "application/merge-patch+json"}), 404)


def test_writes_without_the_token(anon, helpers, unchanged):
    # tdd-things-read-only-auth, exploration-secboot-401
    td = helpers.make_td("urn:example:new")
    for method, path, body, ctype in (
        ("PUT", "/things/urn:example:new", td, "application/td+json"),
        ("PUT", "/things/urn:example:lamp", td, "application/td+json"),
        ("POST", "/things", helpers.make_td(None), "application/td+json"),
        ("PATCH", "/things/urn:example:lamp", {"title": "x"}, "application/merge-patch+json"),
        ("DELETE", "/things/urn:example:lamp", None, None),
    ):
        headers = {"Content-Type": ctype} if ctype else {}
        r = anon.request(method, path, json=body, headers=headers)
        assert_problem(r, 401)
        assert r.headers["www-authenticate"].startswith("Bearer")
    r = anon.put("/things/urn:example:new", json=td, headers={"Authorization": "Bearer wrong"})
    assert_problem(r, 401)
    assert 'error="invalid_token"' in r.headers["www-authenticate"]
    r = anon.put("/things/urn:example:new", json=td, headers={"Authorization": "Basic Zm9vOmJhcg=="})
    assert_problem(r, 401)
    # reads stay open by default
    assert anon.get("/things/urn:example:lamp").status_code == 200


def test_unknown_routes_and_methods(http, unchanged):
    assert_problem(http.get("/nowhere"), 404)
    assert_problem(http.post("/things/urn:example:lamp", json={}), 405)
    assert_problem(http.get("/events/thing_exploded"), 404)
    # tdd-http-unsupported-feature, tdd-search-sparql (not implemented)
    assert_problem(http.get("/search/sparql", params={"query": "SELECT * WHERE {?s ?p ?o}"}), 501)
    assert_problem(http.get("/search/xpath", params={"query": "/"}), 501)


def test_the_directorys_own_td_cannot_be_changed(tdd, http, helpers, unchanged):
    own = tdd.directory.own_id
    assert_problem(http.delete(f"/things/{own}"), 403)
    assert_problem(http.patch(f"/things/{own}", json={"title": "x"},
                              headers={"Content-Type": "application/merge-patch+json"}), 403)
