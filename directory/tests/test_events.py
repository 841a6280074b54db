"""Notifications over Server-Sent Events (WoT Discovery 7.3.2.4): types, filters, diff, resume."""

from __future__ import annotations

import json

import pytest


@pytest.fixture
def listen(tdd, listener_cls):
    opened: list = []

    def open_(path: str = "/events", headers: dict[str, str] | None = None):
        lst = listener_cls(tdd.url, path, headers)
        opened.append(lst)
        return lst

    yield open_
    for lst in opened:
        lst.close()


def test_lifecycle_events(http, helpers, listen):
    # tdd-notification, tdd-notification-sse, tdd-notification-event-id, tdd-notification-event-types,
    # tdd-notification-data, tdd-notification-data-td-id
    lst = listen("/events")
    assert lst.status == 200 and lst.content_type == "text/event-stream"
    http.put("/things/urn:example:lamp", json=helpers.make_td(), headers=helpers.td_headers())
    http.patch("/things/urn:example:lamp", json={"title": "patched"},
               headers={"Content-Type": "application/merge-patch+json"})
    http.delete("/things/urn:example:lamp")
    got = [lst.get() for _ in range(3)]
    assert [e.event for e in got] == ["thing_created", "thing_updated", "thing_deleted"]
    assert all(json.loads(e.data) == {"id": "urn:example:lamp"} for e in got)
    ids = [int(e.id) for e in got]
    assert ids == sorted(ids) and len(set(ids)) == 3


def test_filter_by_event_type(http, helpers, listen):
    # tdd-notification-filter-type
    created = listen("/events/thing_created")
    deleted = listen("/events/thing_deleted")
    http.put("/things/urn:example:a", json=helpers.make_td("urn:example:a"), headers=helpers.td_headers())
    http.put("/things/urn:example:a", json=helpers.make_td("urn:example:a", title="b"),
             headers=helpers.td_headers())
    http.delete("/things/urn:example:a")
    assert created.get().event == "thing_created"
    assert deleted.get().event == "thing_deleted"
    assert created.empty_for(0.3) and deleted.empty_for(0.1)


def test_diff_gives_the_td_and_the_merge_patch(http, helpers, listen):
    # tdd-notification-data-create-full, tdd-notification-data-update-diff, -update-id, -delete-diff
    lst = listen("/events?diff=true")
    td = helpers.make_td(description="old")
    http.put("/things/urn:example:lamp", json=td, headers=helpers.td_headers())
    http.put("/things/urn:example:lamp", json={**td, "title": "new", "description": "x"},
             headers=helpers.td_headers())
    http.patch("/things/urn:example:lamp", json={"description": None},
               headers={"Content-Type": "application/merge-patch+json"})
    http.delete("/things/urn:example:lamp")
    created, upd1, upd2, deleted = (json.loads(lst.get().data) for _ in range(4))
    assert created["id"] == "urn:example:lamp" and created["properties"] == td["properties"]
    assert created["title"] == "lamp" and "registration" in created
    assert upd1["id"] == "urn:example:lamp"
    assert upd1["title"] == "new" and upd1["description"] == "x"
    assert "properties" not in upd1  # only what changed
    assert upd2["id"] == "urn:example:lamp" and upd2["description"] is None
    assert deleted == {"id": "urn:example:lamp"}


def test_resume_with_last_event_id(http, helpers, listen):
    # tdd-notification-event-id: reconnecting clients get every missed event
    lst = listen("/events")
    for i in range(3):
        http.put(f"/things/urn:example:{i}", json=helpers.make_td(f"urn:example:{i}"),
                 headers=helpers.td_headers())
    first = lst.get()
    lst.close()  # the client goes away after the first event
    http.delete("/things/urn:example:0")
    again = listen("/events", headers={"Last-Event-ID": first.id})
    missed = [again.get() for _ in range(3)]
    assert [(e.event, json.loads(e.data)["id"]) for e in missed] == [
        ("thing_created", "urn:example:1"), ("thing_created", "urn:example:2"),
        ("thing_deleted", "urn:example:0")]
    http.put("/things/urn:example:9", json=helpers.make_td("urn:example:9"), headers=helpers.td_headers())
    assert json.loads(again.get().data)["id"] == "urn:example:9"  # then live events, no duplicates
    assert again.empty_for(0.2)
    # resume on a filtered stream replays only that type, with diff if asked
    created = listen("/events/thing_created?diff=true", headers={"Last-Event-ID": first.id})
    replay = [json.loads(created.get().data) for _ in range(3)]
    assert [td["id"] for td in replay] == ["urn:example:1", "urn:example:2", "urn:example:9"]
    assert all("title" in td for td in replay)


def test_bad_event_requests(http):
    assert http.get("/events?diff=maybe").status_code == 400
    assert http.get("/events", headers={"Last-Event-ID": "abc"}).status_code == 400
    r = http.head("/events/thing_updated")
    assert r.status_code == 200 and r.headers["content-type"] == "text/event-stream"


def test_refresh_without_change_emits_nothing(http, helpers, listen):
    lst = listen("/events")
    td = helpers.make_td(registration={"ttl": 60})
    assert http.put("/things/urn:example:lamp", json=td, headers=helpers.td_headers()).status_code == 201
    assert lst.get().event == "thing_created"
    first = http.get("/things/urn:example:lamp").json()["registration"]
    assert http.put("/things/urn:example:lamp", json=td, headers=helpers.td_headers()).status_code == 204
    again = http.get("/things/urn:example:lamp").json()["registration"]
    assert again["modified"] == first["modified"]
    assert again["expires"] > first["expires"]
    assert lst.empty_for(0.3)
