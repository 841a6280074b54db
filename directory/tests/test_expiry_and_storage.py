"""Registration ttl and expiry purge (7.3.1.2), storage through SQLAlchemy, the directory's own TD."""

from __future__ import annotations

import time
from datetime import UTC, datetime, timedelta

import httpx
from sqlalchemy import create_engine, inspect, select
from wott_directory.models import EventRow, ThingRow
from wott_directory.registration import iso
from wott_directory.validation import td_problems


def test_ttl_sets_expires_and_the_td_is_purged(start_directory, helpers, listener_cls):
    # tdd-registrationinfo-vocab-ttl, -vocab-expires, tdd-registrationinfo-expiry-purge
    srv = start_directory(purge_interval=0.1)
    with httpx.Client(base_url=srv.url, headers={"Authorization": f"Bearer {helpers.token}"}) as c:
        lst = listener_cls(srv.url, "/events/thing_deleted")
        far = iso(datetime.now(UTC) + timedelta(days=300))
        td = helpers.make_td(registration={"ttl": 0.6, "expires": far})  # with a ttl, expires is ignored
        assert c.put("/things/urn:example:lamp", json=td, headers=helpers.td_headers()).status_code == 201
        reg = c.get("/things/urn:example:lamp").json()["registration"]
        assert reg["ttl"] == 0.6
        expires = datetime.fromisoformat(reg["expires"])
        modified = datetime.fromisoformat(reg["modified"])
        assert abs((expires - modified).total_seconds() - 0.6) < 0.01
        assert helpers.wait_until(lambda: c.get("/things/urn:example:lamp").status_code == 404, timeout=60)
        ev = lst.get()
        assert ev.event == "thing_deleted" and '"urn:example:lamp"' in ev.data
        lst.close()


def test_refresh_keeps_a_td_alive(start_directory, helpers):
    """Refreshed more often than its ttl, a TD outlives two ttls; left alone, it is purged. The ttl
    (2 s) is eight refresh intervals: only a request stalled for 1.75 s lets it lapse (a
    201 instead of a 204), which no machine short of a hang does."""
    srv = start_directory(purge_interval=0.05)
    ttl = 2.0
    with httpx.Client(base_url=srv.url, headers={"Authorization": f"Bearer {helpers.token}"},
                      timeout=60) as c:
        td = helpers.make_td(registration={"ttl": ttl})
        c.put("/things/urn:example:lamp", json=td, headers=helpers.td_headers())
        start = time.monotonic()
        while time.monotonic() - start < 2 * ttl:
            # nothing to wait for: time itself must pass, less than the ttl between refreshes,
            # and a 204 (not 201) shows the TD was still there when refreshed
            time.sleep(ttl / 8)
            assert c.put("/things/urn:example:lamp", json=td, headers=helpers.td_headers()).status_code == 204
        assert c.get("/things/urn:example:lamp").status_code == 200
        # a PATCH of the ttl alone is a refresh too
        c.patch("/things/urn:example:lamp", json={"registration": {"ttl": 0.5}},
                headers={"Content-Type": "application/merge-patch+json"})
        assert c.get("/things/urn:example:lamp").status_code == 200
        assert helpers.wait_until(lambda: c.get("/things/urn:example:lamp").status_code == 404, timeout=60)


def test_absolute_expires_without_ttl(http, helpers):
    later = iso(datetime.now(UTC) + timedelta(hours=1))
    td = helpers.make_td(registration={"expires": later})
    http.put("/things/urn:example:lamp", json=td, headers=helpers.td_headers())
    assert http.get("/things/urn:example:lamp").json()["registration"]["expires"] == later
    past = helpers.make_td("urn:example:old", registration={"expires": "2001-01-01T00:00:00Z"})
    r = http.put("/things/urn:example:old", json=past, headers=helpers.td_headers())
    assert r.status_code == 400 and r.json()["validationErrors"][0]["field"] == "$.registration.expires"
    bad = helpers.make_td("urn:example:bad", registration={"ttl": -5})
    assert http.put("/things/urn:example:bad", json=bad, headers=helpers.td_headers()).status_code == 400


def test_storage_survives_a_restart(start_directory, helpers, tmp_path, listener_cls, directory_db):
    db = directory_db if directory_db.startswith("postgresql") else f"sqlite:///{tmp_path / 'tdd.db'}"
    first = start_directory(db=db)
    auth = {"Authorization": f"Bearer {helpers.token}"}
    with httpx.Client(base_url=first.url, headers=auth) as c:
        c.put("/things/urn:example:lamp", json=helpers.make_td(), headers=helpers.td_headers())
        c.post("/things", json=helpers.make_td(None, title="anon"), headers=helpers.td_headers())
        c.patch("/things/urn:example:lamp", json={"title": "patched"},
                headers={"Content-Type": "application/merge-patch+json"})
        before = c.get("/things").json()
    first.stop()
    engine = create_engine(db)
    try:
        tables = set(inspect(engine).get_table_names())
        with engine.connect() as conn:
            assert len(conn.execute(select(ThingRow.id)).all()) == 3
            events = conn.execute(select(EventRow.id, EventRow.type).order_by(EventRow.id)).all()
    finally:
        engine.dispose()  # its pooled connections, closed now rather than whenever it is collected
    assert {"tdd_things", "tdd_events"} <= tables
    assert [t for _, t in events][-3:] == ["thing_created", "thing_created", "thing_updated"]

    second = start_directory(db=db)  # another port: another base URL, so a new own TD replaces the old
    with httpx.Client(base_url=second.url, headers=auth) as c:
        after = c.get("/things").json()
        mine = [td for td in after if not td["id"].startswith("urn:uuid:") or td["title"] == "anon"]
        assert [td["title"] for td in mine] == ["patched", "anon"]
        assert [td["id"] for td in after if td.get("@type") == "ThingDirectory"] == [second.directory.own_id]
        assert len(after) == len(before)
        # events persisted too: a client that saw the first event resumes across the restart
        lst = listener_cls(second.url, "/events", headers={"Last-Event-ID": str(events[0][0])})
        replayed = [lst.get().event for _ in range(len(events) - 1)]
        assert replayed[-3:] == ["thing_created", "thing_created", "thing_updated"]
        lst.close()


def test_own_td_at_well_known_and_in_the_listing(tdd, anon):
    # introduction-well-known-path, introduction-well-known-thing-description,
    # exploration-directory-description-type, exploration-server-http-*,
    # introduction-direct-directory-description
    r = anon.get("/.well-known/wot")
    assert r.status_code == 200 and r.headers["content-type"] == "application/td+json"
    td = r.json()
    assert td["@type"] == "ThingDirectory"
    assert "https://www.w3.org/2022/wot/discovery" in td["@context"]
    assert td["base"] == tdd.url
    assert td_problems({k: v for k, v in td.items() if k != "registration"}) == []
    assert td_problems(td) == []
    listed = {t["id"]: t for t in anon.get("/things").json()}
    assert listed[td["id"]]["title"] == td["title"]
    # its security: reads open, writes behind the bearer token
    assert td["securityDefinitions"]["bearer_sc"]["scheme"] == "bearer"
    assert td["security"] == ["nosec_sc"]
    assert td["actions"]["createThing"]["forms"][0]["security"] == ["bearer_sc"]
    assert td["actions"]["retrieveThing"]["forms"][0].get("security") is None
    assert set(td["actions"]) == {"createThing", "createAnonymousThing", "retrieveThing", "updateThing",
                                  "partiallyUpdateThing", "deleteThing", "searchJSONPath"}
    # every form can be followed: hrefs relative to base, ops and methods stated
    for kind in ("properties", "actions", "events"):
        for aff in td[kind].values():
            for form in aff["forms"]:
                assert "op" in form and "htv:methodName" in form and not form["href"].startswith("/")


def test_open_directory_on_loopback(start_directory, helpers):
    # 'open' directories: loopback clients write without a token, and the TD says nosec
    srv = start_directory(token=None, open_writes=True)
    with httpx.Client(base_url=srv.url) as c:
        r = c.put("/things/urn:example:lamp", json=helpers.make_td(), headers=helpers.td_headers())
        assert r.status_code == 201
        td = c.get("/.well-known/wot").json()
        assert td["actions"]["createThing"]["forms"][0]["security"] == ["nosec_sc"]


def test_read_only_and_protected_directories(start_directory, helpers):
    ro = start_directory(token=None)  # no token, not open: nobody can write
    with httpx.Client(base_url=ro.url) as c:
        r = c.put("/things/urn:example:lamp", json=helpers.make_td(), headers=helpers.td_headers())
        assert r.status_code == 403 and r.headers["content-type"] == "application/problem+json"
    prot = start_directory(protect_reads=True)
    with httpx.Client(base_url=prot.url) as c:
        assert c.get("/things").status_code == 401
        assert c.get("/search/jsonpath", params={"query": "$"}).status_code == 401
        assert c.get("/events").status_code == 401
        assert c.get("/.well-known/wot").status_code == 200  # how clients find out what to present
        assert c.get("/things", headers={"Authorization": f"Bearer {helpers.token}"}).status_code == 200


def test_open_writes_refused_off_loopback():
    import pytest
    from wott_directory import ConfigError, DirectorySettings

    with pytest.raises(ConfigError):
        DirectorySettings(open_writes=True).check_bind("0.0.0.0")
    DirectorySettings(open_writes=True).check_bind("127.0.0.1")


def test_freeze_gc_keeps_tds_out_of_the_collector(start_directory, helpers):
    import gc

    gc.unfreeze()
    try:
        srv = start_directory(freeze_gc=True, freeze_every=2)
        frozen = gc.get_freeze_count()
        assert frozen > 0
        with httpx.Client(base_url=srv.url, headers={"Authorization": f"Bearer {helpers.token}"}) as c:
            for i in range(2):
                c.put(f"/things/urn:example:{i}", json=helpers.make_td(f"urn:example:{i}"),
                      headers=helpers.td_headers())
        assert gc.get_freeze_count() > frozen  # the new TDs were frozen after 2 writes
    finally:
        gc.unfreeze()
