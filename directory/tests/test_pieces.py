"""Issue 47: the pieces ``Directory`` composes, each on its own: the TDs in memory (``store.Catalogue``),
when registrations run out (``expiry.Expiry``), and the bounded thread writes and searches run on
(``threads.WorkThread``)."""

from __future__ import annotations

import asyncio
import threading
from datetime import UTC, datetime, timedelta

import pytest
from wott_directory.errors import DirectoryError
from wott_directory.expiry import Expiry
from wott_directory.registration import Enriched, plan_write
from wott_directory.store import Catalogue, StoredThing
from wott_directory.threads import WorkThread
from wott_directory.validation import MAX_TD_DEPTH

NOW = datetime(2026, 12, 7, 12, 0, tzinfo=UTC)


def _td(thing_id: str, **more) -> dict:
    return {"@context": "https://www.w3.org/2022/wot/td/v1.1", "id": thing_id, "title": thing_id,
            "securityDefinitions": {"nosec_sc": {"scheme": "nosec"}}, "security": "nosec_sc", **more}


def _deep(levels: int) -> dict:
    doc: dict = {}
    for _ in range(levels):
        doc = {"a": doc}
    return doc


def test_the_catalogue_keeps_what_reads_need_in_step_with_what_is_stored():
    cat = Catalogue()
    deep = _td("urn:c", nested=_deep(MAX_TD_DEPTH + 2))
    cat.load([StoredThing("urn:b", _td("urn:b"), anonymous=True, size=100),
              StoredThing("urn:c", deep, anonymous=False, size=50),
              StoredThing("urn:tdd", _td("urn:tdd"), anonymous=False, own=True, size=10)])
    assert cat.ids == ["urn:b", "urn:c", "urn:tdd"] and cat.stored_bytes == 160
    assert cat.anonymous == {"urn:b"} and cat.own == {"urn:tdd"} and cat.unsearchable == {"urn:c"}
    assert [td["id"] for td in cat.snapshot()] == ["urn:b", "urn:tdd"]  # too deep to search: left out
    assert cat.snapshot() is cat.snapshot()  # shared until something changes
    etag, array = cat.etag, cat.snapshot()
    plan = plan_write("urn:a", _td("urn:a"), None, NOW)
    cat.stored("urn:a", plan.rec, plan.size, anonymous=False)
    cat.held.add("urn:a")
    assert cat.ids == ["urn:a", "urn:b", "urn:c", "urn:tdd"] and cat.stored_bytes == 160 + plan.size
    assert cat.etag != etag and cat.snapshot() is not array and len(cat.snapshot()) == 3
    again = plan_write("urn:c", _td("urn:c"), cat.things["urn:c"], NOW)  # replaced by a shallow one
    cat.stored("urn:c", again.rec, again.size, anonymous=False)
    assert "urn:c" not in cat.unsearchable and cat.stored_bytes == 110 + plan.size + again.size
    assert [td["id"] for td in cat.page(1, 2)] == ["urn:b", "urn:c"]
    row = cat.row("urn:tdd", cat.things["urn:tdd"], anonymous=False)
    assert row["own"] is True and row["id"] == "urn:tdd"
    cat.removed("urn:a")
    cat.removed("urn:b")
    assert cat.ids == ["urn:c", "urn:tdd"] and cat.held == set() and cat.anonymous == set()
    assert cat.stored_bytes == 10 + again.size


def test_expiry_yields_what_ran_out_and_skips_entries_a_later_write_made_stale():
    cat = Catalogue()
    exp = Expiry()

    def put(thing_id: str, ttl_s: float) -> None:
        plan = plan_write(thing_id, _td(thing_id, registration={"ttl": ttl_s}), cat.things.get(thing_id), NOW)
        cat.stored(thing_id, plan.rec, plan.size, anonymous=False)
        exp.add(thing_id, plan.rec)

    put("urn:soon", 10)
    put("urn:later", 100)
    put("urn:renewed", 10)
    put("urn:renewed", 1000)  # re-registered: its first entry is stale
    put("urn:gone", 10)
    cat.removed("urn:gone")  # deleted: its entry is stale
    never = plan_write("urn:never", _td("urn:never"), None, NOW).rec
    exp.add("urn:never", never)  # no expires: nothing to purge
    at = (NOW + timedelta(seconds=50)).timestamp()
    assert exp.due(at) and not exp.due(NOW.timestamp())
    assert list(exp.pop_due(at, cat.things.get)) == ["urn:soon"]
    assert not exp.due(at)
    tomorrow = (NOW + timedelta(days=1)).timestamp()
    assert list(exp.pop_due(tomorrow, cat.things.get)) == ["urn:later", "urn:renewed"]
    assert isinstance(never, Enriched) and never.expires is None


def test_the_work_thread_refuses_a_client_past_its_bound_and_lets_the_embedder_wait():
    async def scenario() -> None:
        work = WorkThread("test-work", 1, "writes", "MAX_TEST")
        gate = threading.Event()
        first = asyncio.ensure_future(work.run(gate.wait, 30))
        await asyncio.sleep(0)  # the first call holds the thread
        with pytest.raises(DirectoryError) as refused:
            await work.run(lambda: None)
        assert refused.value.status == 503
        assert "1 writes are already waiting (MAX_TEST)" in refused.value.detail
        assert refused.value.headers == {"Retry-After": "1"}
        own = asyncio.ensure_future(work.run(lambda: "done", bounded=False))  # waits its turn
        with pytest.raises(TimeoutError):
            await work.run(lambda: None, bounded=False, timeout_s=0.05)
        gate.set()
        assert await first is True and await own == "done" and work.pending == 0
        work.shutdown()

    asyncio.run(asyncio.wait_for(scenario(), 60))

