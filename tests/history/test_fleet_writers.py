"""Issue 13, item 2: hubs of different ids record into one database side by side and lose nothing;
a second process of the *same* hub id is still refused (issue 16, item 4).

Each writer is a real process; the database is an SQLite file (WAL) or a fresh PostgreSQL
database (``database`` fixture of conftest.py).
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from wott_hub.errors import Conflict, InvalidInput
from wott_hub.history import HistoryReader, HistoryWriter, create_engine
from wott_hub.history.lease import Lease

N = 6000  # records per Thing; 2 Things per hub, written in many small interleaved batches

_WRITER = textwrap.dedent("""
    import json, sys
    from wott_hub.events.record import KIND_EVENT, Record
    from wott_hub.history import HistoryWriter, create_engine, upgrade
    url, hub, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
    eng = create_engine(url)
    upgrade(eng)
    w = HistoryWriter(eng, interval_s=0.002, batch_max=300, hub_id=hub)
    things = [f"urn:{hub}:device:{k}" for k in (1, 2)]
    starts = {t: w.register_thing(t, title=t) for t in things}
    w.start()
    print("ready", flush=True)
    sys.stdin.readline()  # "go": both hubs write at the same time
    for i in range(n):
        for t in things:
            seq = starts[t] + i + 1
            w.submit(Record(t, seq, KIND_EVENT, "tick", 10**18 + i, json.dumps({"hub": hub, "i": i})))
    ok = w.flush(120)
    w.stop()
    print("done" if ok and w.failed_records == 0 and w.dropped == 0 else f"lost {w.health()}", flush=True)
""")

_SAME_ID = textwrap.dedent("""
    import sys
    from wott_hub.errors import Conflict
    from wott_hub.history import HistoryWriter, create_engine
    try:
        HistoryWriter(create_engine(sys.argv[1]), hub_id=sys.argv[2]).register_thing("urn:other")
    except Conflict as e:
        print(e)
        sys.exit(4)
    print("took it")
""")


def _popen(code: str, *args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", code, *args], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_two_hubs_write_one_database_concurrently_and_lose_nothing(database, engine):
    hubs = [_popen(_WRITER, database, hub, str(N)) for hub in ("hub-a", "hub-b")]
    try:
        for p in hubs:
            assert p.stdout.readline().strip() == "ready", p.stderr.read()
        # while both hold their leases: a process claiming hub-a's identity is refused
        same = subprocess.run([sys.executable, "-c", _SAME_ID, database, "hub-a"], capture_output=True,
                              text=True, timeout=60)
        assert same.returncode == 4, same.stderr
        assert "same hub id 'hub-a'" in same.stdout and f"process {hubs[0].pid}" in same.stdout
        for p in hubs:
            p.stdin.write("go\n")
            p.stdin.flush()
        outs = [p.communicate(timeout=180) for p in hubs]
    finally:
        for p in hubs:
            if p.poll() is None:
                p.kill()
                p.wait(10)
    for p, (out, err) in zip(hubs, outs, strict=True):
        assert p.returncode == 0 and out.strip() == "done", err[-2000:]
    reader = HistoryReader(engine)
    for hub in ("hub-a", "hub-b"):
        for k in (1, 2):
            rows = [row for page in reader.pages(f"urn:{hub}:device:{k}", page=5000) for row in page]
            assert [r.seq for r in rows] == list(range(1, N + 1))  # every record, in order, no hole
            assert all(f'"hub": "{hub}"' in r.data for r in rows)  # nobody wrote into another's Thing
    # both released at their clean stop
    assert Lease(engine, hub_id="hub-a").holder() is None and Lease(engine, hub_id="hub-b").holder() is None
    # the history command reads the shared database by its URL (or file)
    wott_hub = str(Path(sys.executable).parent / "wott-hub")
    listing = subprocess.run([wott_hub, "history", "list", "--database", database, "--json", "--count"],
                             capture_output=True, text=True, timeout=60)
    assert listing.returncode == 0, listing.stderr
    assert {t["id"]: t["count"] for t in json.loads(listing.stdout)} == {
        f"urn:{hub}:device:{k}": N for hub in ("hub-a", "hub-b") for k in (1, 2)}


def test_one_process_may_write_as_two_hub_ids_but_not_take_a_held_id_from_another(engine):
    a = HistoryWriter(engine, interval_s=0.01, hub_id="hub-a")
    b = HistoryWriter(engine, interval_s=0.01, hub_id="hub-b")
    try:
        assert a.register_thing("urn:a:1") == 0 and b.register_thing("urn:b:1") == 0
        assert a.storage.lease.held and b.storage.lease.held
        holder = Lease(engine, hub_id="hub-a").holder()
        assert holder is not None and holder.holder == a.storage.lease.me
        with engine.begin() as conn:  # hub-a's row held by a live process of another host
            conn.exec_driver_sql("UPDATE hub_lease SET holder='elsewhere', pid=1, host='h' "
                                 "WHERE hub_id='hub-a'")
        with pytest.raises(Conflict, match="same hub id 'hub-a'"):
            Lease(engine, hub_id="hub-a").acquire()
        fresh = Lease(engine, hub_id="hub-c")  # a new id gets its own row at once
        fresh.acquire()
        assert fresh.held
        fresh.release()
    finally:
        a.stop()
        b.stop()


def test_a_thing_recorded_by_a_live_hub_is_refused_to_a_hub_of_another_id(engine, make_records):
    a = HistoryWriter(engine, interval_s=0.01, hub_id="hub-a")
    b = HistoryWriter(engine, interval_s=0.01, hub_id="hub-b")
    try:
        start = a.register_thing("urn:wott-hub:device:barrel-1")
        a.start()
        for r in make_records("urn:wott-hub:device:barrel-1", start, 10):
            a.submit(r)
        assert a.flush()
        # two hubs configured with the same Thing id: the second is refused, naming the first
        with pytest.raises(Conflict, match="recorded .* by hub 'hub-a'.*own identity"):
            b.register_thing("urn:wott-hub:device:barrel-1")
        a.stop()  # hub-a is gone (clean stop: lease released): hub-b continues its sequence
        assert b.register_thing("urn:wott-hub:device:barrel-1") == 10
    finally:
        a.stop()
        b.stop()


@pytest.mark.parametrize("bad", ["", "   ", "x" * 201, None, 7])
def test_a_hub_id_that_cannot_key_a_lease_is_refused_up_front(tmp_path, bad):
    engine = create_engine(f"sqlite:///{tmp_path / 'h.db'}")
    with pytest.raises(InvalidInput, match="hub id"):
        HistoryWriter(engine, hub_id=bad)


_UPGRADE = textwrap.dedent("""
    import sys
    from wott_hub.history import create_engine, upgrade
    print(upgrade(create_engine(sys.argv[1])))
""")


def test_hubs_starting_together_on_an_empty_postgresql_database_migrate_it_once(pg_url):
    from wott_hub.history.db import current_revision
    from wott_hub.history.models import HEAD_REVISION

    procs = [_popen(_UPGRADE, pg_url) for _ in range(3)]
    outs = [p.communicate(timeout=120) for p in procs]
    assert [(p.returncode, out.strip()) for p, (out, _) in zip(procs, outs, strict=True)] == \
        [(0, HEAD_REVISION)] * 3, [err[-1500:] for _, err in outs]
    engine = create_engine(pg_url)
    try:
        assert current_revision(engine) == HEAD_REVISION
        assert Lease(engine).holder() is None  # the default hub's row, created once
        with engine.connect() as conn:
            assert conn.exec_driver_sql("SELECT count(*) FROM hub_lease").scalar() == 1
    finally:
        engine.dispose()
