"""Issue 16, item 4: the history writer never wedges on one bad batch, and one writer per database.

Real SQLite files; the "second hub" is a second real process (the lease is per process).
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import textwrap
import time

import pytest
import sqlalchemy as sa

from wott_hub.errors import Conflict, HistoryError
from wott_hub.events.record import KIND_EVENT, Record
from wott_hub.history import HistoryReader, HistoryWriter, create_engine, database_url, upgrade
from wott_hub.history.lease import Lease


@pytest.fixture
def engine(tmp_path):
    eng = create_engine(database_url(tmp_path / "h.db"))
    upgrade(eng)
    yield eng
    eng.dispose()


def _recs(thing: str, after: int, n: int) -> list[Record]:
    return [Record(thing, after + i + 1, KIND_EVENT, "tick", 10**18 + after + i, json.dumps({"i": i}))
            for i in range(n)]


def _seqs(engine, thing: str) -> list[int]:
    return [r.seq for page in HistoryReader(engine).pages(thing) for r in page]


def test_a_unique_key_conflict_is_isolated_reported_and_the_writer_carries_on(engine):
    watermarks: list[dict[str, int]] = []
    w = HistoryWriter(engine, interval_s=0.01, on_commit=watermarks.append)
    start = w.register_thing("d")
    key = w.storage.keys["d"]
    # what a second hub did (issue 16): a row with a seq this writer is about to write
    with engine.begin() as conn:
        conn.exec_driver_sql("INSERT INTO events (thing_key, seq, t_ns, kind, name, data) "
                             f"VALUES ({key}, {start + 37}, {10**18 + 36}, 0, 'tick', '\"theirs\"')")
    w.start()
    try:
        for r in _recs("d", start, 100):
            w.submit(r)
        assert w.flush(10)
        assert (w.written, w.failed_records) == (99, 1)
        h = w.health()
        assert h["state"] == "degraded" and h["failedRecords"] == 1
        assert f"seq {start + 37}" in h["lastError"] and "UNIQUE" in h["lastError"]
        assert w.failed_seqs["d"] == {start + 37}
        # every record got past the watermark (the refused one given up on): nobody waits for it
        assert max(m.get("d", 0) for m in watermarks) == start + 100
        # and it keeps writing
        for r in _recs("d", start + 100, 50):
            w.submit(r)
        assert w.flush(10)
        assert w.written == 149
    finally:
        w.stop()
    assert _seqs(engine, "d") == list(range(start + 1, start + 151))  # theirs kept at 37, ours around it


def test_health_is_degraded_while_batches_fail_and_ok_again_after(engine):
    impatient = create_engine(database_url(engine.url.database))

    @sa.event.listens_for(impatient, "connect")
    def _no_wait(dbapi_conn, _rec):  # after the hub's own pragmas: fail at once on a lock
        dbapi_conn.execute("PRAGMA busy_timeout=20")

    w = HistoryWriter(impatient, interval_s=0.01)
    start = w.register_thing("d")
    w.start()
    blocker = engine.connect()
    try:
        # another connection holds SQLite's write lock: batches fail (not the rows' fault) and are retried
        blocker.exec_driver_sql("BEGIN IMMEDIATE")
        for r in _recs("d", start, 10):
            w.submit(r)
        deadline = time.monotonic() + 10
        while w.health()["state"] == "ok" and time.monotonic() < deadline:
            time.sleep(0.02)
        h = w.health()
        assert h["state"] == "degraded" and "locked" in h["reason"] and h["errors"] >= 1
        assert w.written == 0 and w.failed_records == 0  # nothing given up: only retried
        blocker.exec_driver_sql("ROLLBACK")
        assert w.flush(15)
        assert w.health()["state"] == "ok" and w.written == 10
    finally:
        blocker.close()
        w.stop()
        impatient.dispose()
    assert _seqs(engine, "d") == list(range(start + 1, start + 11))


_HOLDER = textwrap.dedent("""
    import sys, time
    from wott_hub.history import HistoryWriter, create_engine, database_url, upgrade
    eng = create_engine(database_url(sys.argv[1]))
    upgrade(eng)
    w = HistoryWriter(eng, interval_s=0.01)
    w.register_thing("d")
    w.start()
    print("ready", flush=True)
    time.sleep(60)
""")

_SECOND = textwrap.dedent("""
    import sys
    from wott_hub.errors import Conflict
    from wott_hub.history import HistoryWriter, create_engine, database_url, upgrade
    eng = create_engine(database_url(sys.argv[1]))
    upgrade(eng)
    try:
        HistoryWriter(eng).register_thing("d")
    except Conflict as e:
        print(e)
        sys.exit(4)
    print("took it")
""")


def _python(code: str, *args: str, timeout: float = 20) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True,
                          timeout=timeout)


def test_a_second_process_on_the_same_database_is_refused_until_the_first_is_gone(tmp_path):
    db = str(tmp_path / "h.db")
    first = subprocess.Popen([sys.executable, "-c", _HOLDER, db], stdout=subprocess.PIPE, text=True)
    try:
        assert first.stdout.readline().strip() == "ready"
        second = _python(_SECOND, db)
        assert second.returncode == 4, second.stderr
        msg = second.stdout.strip()
        assert db in msg and f"process {first.pid}" in msg and "in use by another hub" in msg
        assert "Traceback" not in second.stderr
        # the holder dies without a word (SIGKILL): its lease is taken over at once (its pid is gone)
        first.send_signal(signal.SIGKILL)
        first.wait(10)
        third = _python(_SECOND, db)
        assert (third.returncode, third.stdout.strip()) == (0, "took it"), third.stderr
    finally:
        if first.poll() is None:
            first.kill()
            first.wait(10)


def test_a_clean_stop_releases_the_lease_and_a_stale_one_is_taken_over(engine):
    w = HistoryWriter(engine, interval_s=0.01)
    w.register_thing("d")
    w.start()
    assert Lease(engine).holder() is not None
    w.stop()
    assert Lease(engine).holder() is None
    # a live process of this host (pid 1) that stopped refreshing 60 s ago: stale, taken over
    with engine.begin() as conn:
        conn.exec_driver_sql("UPDATE hub_lease SET holder='elsewhere', pid=1, host='h', "
                             f"heartbeat_ns={time.time_ns() - 60 * 10**9} WHERE id=1")
    fresh = Lease(engine, stale_s=30)
    fresh.acquire()
    assert fresh.held
    # the same holder, refreshed a moment ago: refused, naming it
    with engine.begin() as conn:
        conn.exec_driver_sql(f"UPDATE hub_lease SET holder='elsewhere', pid=1, host='h', "
                             f"heartbeat_ns={time.time_ns()} WHERE id=1")
    with pytest.raises(Conflict, match="process 1 on h"):
        Lease(engine).acquire()


def test_a_writer_whose_lease_was_taken_over_stops_recording_and_says_so(engine):
    w = HistoryWriter(engine, interval_s=0.01)
    start = w.register_thing("d")
    w.start()
    try:
        with engine.begin() as conn:
            conn.exec_driver_sql(f"UPDATE hub_lease SET holder='usurper', pid=1, host='h', "
                                 f"heartbeat_ns={time.time_ns()} WHERE id=1")
        w._next_refresh = 0.0  # refresh now rather than in 5 s
        w.submit(_recs("d", start, 1)[0])
        deadline = time.monotonic() + 10
        while w.health()["state"] != "failed" and time.monotonic() < deadline:
            time.sleep(0.02)
        h = w.health()
        assert h["state"] == "failed" and "taken over" in h["reason"]
        for r in _recs("d", start + 1, 5):
            w.submit(r)
        assert w.dropped >= 5
        with pytest.raises(HistoryError, match="taken over"):
            w.register_thing("e")
    finally:
        w.stop()


@pytest.mark.parametrize(("kwargs", "says"), [
    ({"interval_s": 1e300}, "batch interval"),
    ({"interval_s": float("nan")}, "batch interval"),
    ({"batch_max": 0}, "batch size"),
])
def test_settings_that_would_kill_the_writer_thread_are_refused_up_front(engine, kwargs, says):
    from wott_hub.errors import InvalidInput

    with pytest.raises(InvalidInput, match=says):
        HistoryWriter(engine, **kwargs)


@pytest.mark.parametrize("days", [float("inf"), float("nan"), -1.0, 1e9])
def test_a_retention_that_would_fail_every_minute_is_refused_up_front(days):
    from wott_hub.errors import InvalidInput
    from wott_hub.history import Retention

    with pytest.raises(InvalidInput, match="retention days"):
        Retention(days=days)
