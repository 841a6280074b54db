"""Create, retrieve, update, merge-patch and delete TDs over HTTP (WoT Discovery 7.3.2.1).

Each test names the assertion ids of the spec it covers (see docs/discovery-coverage.md).
"""

from __future__ import annotations

import re
import uuid
from datetime import datetime
from urllib.parse import quote

RFC3339 = re.compile(r"^\d{4}-\d{2}-\d{2}T\d{2}:\d{2}:\d{2}(\.\d+)?Z$")


def test_create_with_put_then_retrieve(http, helpers):
    # tdd-things-create-known-td, -contenttype, -td-resp, tdd-things-retrieve, -resp, -resp-content-type
    td = helpers.make_td("urn:example:lamp")
    r = http.put("/things/urn:example:lamp", json=td, headers=helpers.td_headers())
    assert r.status_code == 201
    assert r.content == b""
    r = http.get("/things/urn:example:lamp")
    assert r.status_code == 200
    assert r.headers["content-type"] == "application/td+json"
    got = r.json()
    assert got["id"] == "urn:example:lamp"
    assert got["title"] == "lamp"
    assert got["properties"] == td["properties"]


def test_served_td_is_enriched(http, helpers):
    # tdd-context-injection, tdd-absolute-time, tdd-registrationinfo-vocab-created/-modified/-retrieved
    http.put("/things/urn:example:lamp", json=helpers.make_td(), headers=helpers.td_headers())
    got = http.get("/things/urn:example:lamp").json()
    assert got["@context"] == ["https://www.w3.org/2022/wot/td/v1.1", "https://www.w3.org/2022/wot/discovery"]
    reg = got["registration"]
    for key in ("created", "modified", "retrieved"):
        assert RFC3339.match(reg[key]), reg
    assert "expires" not in reg and "ttl" not in reg
    later = http.get("/things/urn:example:lamp").json()["registration"]
    assert later["created"] == reg["created"]
    assert datetime.fromisoformat(later["retrieved"]) >= datetime.fromisoformat(reg["retrieved"])


def test_client_registration_times_are_ignored(http, helpers):
    # tdd-registrationinfo-vocab-created/-modified: the directory owns them
    td = helpers.make_td(registration={"created": "2001-01-01T00:00:00Z", "modified": "2001-01-01T00:00:00Z"})
    http.put("/things/urn:example:lamp", json=td, headers=helpers.td_headers())
    reg = http.get("/things/urn:example:lamp").json()["registration"]
    assert not reg["created"].startswith("2001") and not reg["modified"].startswith("2001")


def test_head_returns_the_headers_of_get(http, helpers):
    # tdd-http-head, exploration-server-http-head
    http.put("/things/urn:example:lamp", json=helpers.make_td(), headers=helpers.td_headers())
    for path in ("/things/urn:example:lamp", "/things", "/.well-known/wot",
                 "/search/jsonpath?query=%24%5B*%5D.id"):
        get, head = http.get(path), http.head(path)
        assert head.status_code == get.status_code == 200, path
        assert head.content == b""
        assert head.headers["content-type"] == get.headers["content-type"]
        if path != "/things/urn:example:lamp":  # retrieved time may tick between the two
            assert head.headers["content-length"] == get.headers["content-length"]
    assert http.head("/things/urn:example:nothing").status_code == 404


def test_update_with_put_replaces(http, helpers):
    # tdd-things-update, -contenttype, -update-resp
    http.put("/things/urn:example:lamp", json=helpers.make_td(), headers=helpers.td_headers())
    created = http.get("/things/urn:example:lamp").json()["registration"]["created"]
    r = http.put("/things/urn:example:lamp", json=helpers.make_td(title="lamp 2", description="new"),
                 headers=helpers.td_headers())
    assert r.status_code == 204 and r.content == b""
    got = http.get("/things/urn:example:lamp").json()
    assert got["title"] == "lamp 2" and got["description"] == "new"
    assert got["registration"]["created"] == created
    assert got["registration"]["modified"] >= created


def test_patch_is_a_json_merge_patch(http, helpers):
    # tdd-things-update-partial, -mergepatch, -contenttype, -partialtd, -resp
    td = helpers.make_td(description="old", tags={"a": 1, "b": 2})
    http.put("/things/urn:example:lamp", json=td, headers=helpers.td_headers())
    patch = {"title": "patched", "description": None, "tags": {"a": None, "c": 3}}
    r = http.patch("/things/urn:example:lamp", json=patch,
                   headers={"Content-Type": "application/merge-patch+json"})
    assert r.status_code == 204
    got = http.get("/things/urn:example:lamp").json()
    assert got["title"] == "patched"
    assert "description" not in got
    assert got["tags"] == {"b": 2, "c": 3}
    assert got["properties"] == td["properties"]


def test_patch_needs_the_merge_patch_content_type(http, helpers):
    # tdd-things-update-partial-contenttype
    http.put("/things/urn:example:lamp", json=helpers.make_td(), headers=helpers.td_headers())
    r = http.patch("/things/urn:example:lamp", json={"title": "x"})
    assert r.status_code == 415
    assert r.headers["content-type"] == "application/problem+json"
    assert http.get("/things/urn:example:lamp").json()["title"] == "lamp"


def test_patch_result_is_validated(http, helpers):
    # tdd-things-update-partial-partialtd, tdd-validation-result: validation after the patch
    http.put("/things/urn:example:lamp", json=helpers.make_td(), headers=helpers.td_headers())
    before = http.get("/things/urn:example:lamp").json()
    r = http.patch("/things/urn:example:lamp", json={"security": None, "title": 42},
                   headers={"Content-Type": "application/merge-patch+json"})
    assert r.status_code == 400
    problem = r.json()
    fields = {e["field"] for e in problem["validationErrors"]}
    assert "$.security" in fields and "$.title" in fields
    after = http.get("/things/urn:example:lamp").json()
    before["registration"].pop("retrieved")
    after["registration"].pop("retrieved")
    assert after == before


def test_patch_cannot_change_the_id_and_must_be_an_object(http, helpers):
    http.put("/things/urn:example:lamp", json=helpers.make_td(), headers=helpers.td_headers())
    mp = {"Content-Type": "application/merge-patch+json"}
    r = http.patch("/things/urn:example:lamp", json={"id": "urn:example:other"}, headers=mp)
    assert r.status_code == 400 and r.json()["validationErrors"][0]["field"] == "$.id"
    r = http.patch("/things/urn:example:lamp", content=b"[1, 2]", headers=mp)
    assert r.status_code == 400
    assert http.patch("/things/urn:example:nothing", json={"title": "x"}, headers=mp).status_code == 404


def test_delete(http, helpers):
    # tdd-things-delete, tdd-things-delete-resp
    http.put("/things/urn:example:lamp", json=helpers.make_td(), headers=helpers.td_headers())
    r = http.delete("/things/urn:example:lamp")
    assert r.status_code == 204 and r.content == b""
    r = http.get("/things/urn:example:lamp")
    assert r.status_code == 404
    assert r.headers["content-type"] == "application/problem+json"
    assert r.json()["status"] == 404
    assert http.delete("/things/urn:example:lamp").status_code == 404


def test_anonymous_td_gets_a_urn_uuid(http, helpers):
    # tdd-things-create-anonymous-td, -contenttype, -id, -td-resp,
    # tdd-anonymous-td-identifier, tdd-anonymous-td-local-uuid, tdd-things-create-known-vs-anonymous
    r = http.post("/things", json=helpers.make_td(None), headers=helpers.td_headers())
    assert r.status_code == 201
    location = r.headers["location"]
    assert location.startswith(http.base_url.__str__() + "things/urn:uuid:")
    thing_id = location.rsplit("/things/", 1)[1]
    assert uuid.UUID(thing_id.removeprefix("urn:uuid:")).version == 4
    got = httpx_get(http, location)
    assert got["id"] == thing_id
    listed = [td["id"] for td in http.get("/things").json()]
    assert thing_id in listed
    assert http.get("/search/jsonpath", params={"query": "$[?@.title=='lamp'].id"}).json() == [thing_id]
    # the anonymous TD, now with its id, can be replaced like any other
    r = http.put(f"/things/{thing_id}", json={**got, "title": "lamp 3"}, headers=helpers.td_headers())
    assert r.status_code == 204


def httpx_get(http, url):
    r = http.get(url)
    assert r.status_code == 200, r.text
    return r.json()


def test_post_with_an_id_and_put_without_are_refused(http, helpers):
    # tdd-things-create-known-vs-anonymous
    r = http.post("/things", json=helpers.make_td("urn:example:lamp"), headers=helpers.td_headers())
    assert r.status_code == 400 and r.json()["validationErrors"][0]["field"] == "$.id"
    r = http.put("/things/urn:example:lamp", json=helpers.make_td(None), headers=helpers.td_headers())
    assert r.status_code == 400
    r = http.put("/things/urn:example:other", json=helpers.make_td("urn:example:lamp"),
                 headers=helpers.td_headers())
    assert r.status_code == 400
    assert [td["id"] for td in http.get("/things").json() if td["id"].startswith("urn:example")] == []


def test_ids_with_reserved_characters_round_trip(http, helpers):
    thing_id = "https://example.com/things/lamp?x=1"
    url = "/things/" + quote(thing_id, safe="")
    assert http.put(url, json=helpers.make_td(thing_id), headers=helpers.td_headers()).status_code == 201
    assert http.get(url).json()["id"] == thing_id
    assert http.delete(url).status_code == 204


def test_json_and_ld_json_bodies_are_accepted(http, helpers):
    # tdd-things-representation-alternate-input (JSON variants)
    for i, ctype in enumerate(("application/json", "application/ld+json")):
        r = http.put(f"/things/urn:example:{i}", json=helpers.make_td(f"urn:example:{i}"),
                     headers={"Content-Type": ctype})
        assert r.status_code == 201
    r = http.put("/things/urn:example:x", content=b"<td/>", headers={"Content-Type": "application/xml"})
    assert r.status_code == 415
