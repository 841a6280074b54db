"""Issue 47: the history writer's pieces on their own (``batch_writer``, ``forward``, ``record_queue``,
``lease.Lease.keep``, ``writer_loop``), against a real SQLite file and a real PostgreSQL database
(the ``engine`` fixture, tests/history/conftest.py): forwarding order, the bisection isolating
refused records, the lease kept by the writer's thread; and the queue's bound in bytes (issue 48,
item 4), on its own and through the whole writer."""

from __future__ import annotations

import json
import time
from types import SimpleNamespace

import pytest
import sqlalchemy as sa

from wott_hub.events.record import KIND_EVENT, Record
from wott_hub.history import HistoryWriter, create_engine, database_url, open_storage, upgrade
from wott_hub.history.batch_writer import RESERVE, BatchWriter
from wott_hub.history.forward import StoreAndForward
from wott_hub.history.lease import Lease
from wott_hub.history.record_queue import RecordQueue, record_bytes
from wott_hub.history.retention import Retention, RetentionClock
from wott_hub.history.spool import Spool
from wott_hub.history.tally import Tally
from wott_hub.history.writer_loop import WriterLoop


def _recs(thing: str, after: int, n: int, pad: int = 0) -> list[Record]:
    return [Record(thing, after + i + 1, KIND_EVENT, "tick", 10**18 + after + i,
                   json.dumps({"i": after + i + 1, "pad": "x" * pad})) for i in range(n)]


def _pieces(engine, *, batch_max: int = 100, spool: Spool | None = None, max_bytes: int = 1 << 24):
    """The pieces as ``HistoryWriter`` composes them, the lease taken."""
    storage = open_storage(engine)
    storage.lease.acquire()
    told: list[dict[str, int]] = []
    tally = Tally(told.append)
    queue = RecordQueue(max_records=RESERVE // 2, max_bytes=max_bytes, batch_max=batch_max)
    batches = BatchWriter(storage, queue, tally, storage.lease, batch_max=batch_max, process=None)
    forward = StoreAndForward(spool, storage, queue, tally, batches, storage.state)
    forward.open()
    return SimpleNamespace(storage=storage, tally=tally, told=told, queue=queue, batches=batches,
                           forward=forward)


def _register(p, thing: str) -> int:
    """What ``HistoryWriter.register_thing`` does with the pieces."""
    start = p.storage.register(thing, title=thing, family="", td=None, static_values=None, ahead=RESERVE)
    p.batches.reserved[thing] = start + RESERVE
    p.tally.committed[thing] = p.tally.started[thing] = start
    return start


def _stored(engine, thing: str) -> list[int]:
    """The Thing's seqs in the order their rows were inserted."""
    with engine.connect() as conn:
        return list(conn.execute(sa.text("SELECT e.seq FROM events e JOIN things t ON t.key = e.thing_key "
                                          "WHERE t.id = :t ORDER BY e.id"), {"t": thing}).scalars())


def _spooled(p, records: list[Record]) -> list[tuple[str, int, int, str, int, bytes]]:
    payloads = p.storage.encode(records)
    return [(r.thing, r.seq, r.kind, r.name, r.t_ns, d) for r, d in zip(records, payloads, strict=True)]


# --- store and forward ---------------------------------------------------------------------------


def test_the_spool_is_forwarded_oldest_first_leaving_out_rows_the_database_has(engine, tmp_path):
    spool = Spool(tmp_path / "spool", 1 << 26, segment_bytes=1 << 12)  # many small segments
    p = _pieces(engine, spool=spool)
    a, b = _register(p, "a"), _register(p, "b")
    ra, rb = _recs("a", a, 300), _recs("b", b, 300)
    for i in range(0, 300, 30):  # the two Things interleaved, as the queue held them
        spool.append(_spooled(p, ra[i:i + 30] + rb[i:i + 30]))
    p.forward.note()
    assert p.storage.state.forwarding.startswith("600 records wait in the spool")
    p.batches.write(ra[50:100])  # committed before a crash, its segment not yet consumed
    for _ in range(100):  # a slice of FORWARD_SLICE_S at a time
        if not p.forward.waiting:
            break
        p.forward.forward()
    assert p.forward.waiting == 0 and spool.records == 0 and p.storage.state.forwarding == ""
    assert _stored(engine, "a") == list(range(a + 51, a + 101)) + list(range(a + 1, a + 51)) \
        + list(range(a + 101, a + 301))  # each once, the rest in the order they were made
    assert _stored(engine, "b") == list(range(b + 1, b + 301))
    assert p.tally.forwarded == 550 and p.tally.failed_records == 0
    assert max(t.get("a", 0) for t in p.told) == a + 300 and max(t.get("b", 0) for t in p.told) == b + 300
    spool.close()


def test_spilled_records_are_durable_at_once_and_come_back_before_what_was_queued_after(engine, tmp_path):
    spool = Spool(tmp_path / "spool", 1 << 26)
    p = _pieces(engine, spool=spool)
    start = _register(p, "d")
    recs = _recs("d", start, 250)
    for r in recs[:200]:
        assert p.queue.offer(r)
    p.forward.spill()
    assert len(p.queue) == 0 and p.queue.bytes == 0 and spool.records == 200 and p.tally.spooled == 200
    assert p.told == [{"d": start + 200}]  # on disk: durable, as a commit is
    for r in recs[200:]:
        assert p.queue.offer(r)
    p.forward.forward()  # the spool first
    p.batches.write_pending(lambda: True)  # then the queue
    assert _stored(engine, "d") == list(range(start + 1, start + 251))
    assert p.tally.written == 250 and p.tally.forwarded == 200
    spool.close()


def test_spooled_records_of_a_thing_the_database_does_not_know_are_counted_and_named(engine, tmp_path):
    spool = Spool(tmp_path / "spool", 1 << 26)
    p = _pieces(engine, spool=spool)
    start = _register(p, "d")
    spool.append(_spooled(p, _recs("ghost", 0, 7) + _recs("d", start, 3)))
    p.forward.forward()
    assert _stored(engine, "d") == [start + 1, start + 2, start + 3]
    assert p.tally.failed_records == 7 and "'ghost'" in p.tally.last_error and spool.records == 0
    spool.close()


def test_without_a_spool_a_spill_keeps_the_records_queued_in_order(engine):
    p = _pieces(engine)
    start = _register(p, "d")
    for r in _recs("d", start, 30):
        p.queue.offer(r)
    p.forward.spill()
    assert [r.seq for r in p.queue.drain()] == list(range(start + 1, start + 31)) and p.told == []


# --- batches ---------------------------------------------------------------------------------------


def test_records_the_database_refuses_are_isolated_by_bisection_and_the_rest_written(engine):
    p = _pieces(engine)
    start = _register(p, "d")
    recs = _recs("d", start, 64)
    p.batches.write([recs[9], recs[40]])  # those two seqs are taken: a unique-key conflict each
    assert p.tally.batches == 1
    p.batches.write_isolating(recs)
    assert p.tally.failed_records == 2 and p.tally.failed_seqs == {"d": {start + 10, start + 41}}
    assert f"d seq {start + 41} not recorded" in p.tally.last_error
    assert _stored(engine, "d") == [start + 10, start + 41] + [s for s in range(start + 1, start + 65)
                                                               if s not in (start + 10, start + 41)]
    assert p.tally.written == 2 + 62
    assert p.tally.batches - 1 <= 2 * 6  # at most log2(64) = 6 transactions more per refused record
    assert p.tally.committed["d"] == start + 64 and {"d": start + 10} in p.told  # given up: told as done
    assert len(p.queue) == 0 and p.queue.inflight == []


def test_a_batch_that_fails_for_another_reason_goes_back_to_the_head_of_the_queue_in_order(tmp_path):
    db = create_engine(database_url(tmp_path / "h.db"))
    upgrade(db)
    eng = create_engine(database_url(tmp_path / "h.db"))

    @sa.event.listens_for(eng, "connect")
    def _no_wait(dbapi_conn, _rec):  # a held lock fails a batch at once
        dbapi_conn.execute("PRAGMA busy_timeout=20")

    p = _pieces(eng, batch_max=100)
    start = _register(p, "d")
    for r in _recs("d", start, 250):
        p.queue.offer(r)
    size = p.queue.bytes
    blocker = db.connect()
    blocker.exec_driver_sql("BEGIN IMMEDIATE")
    try:
        with pytest.raises(Exception, match="locked"):
            p.batches.write_pending(lambda: True)
        assert len(p.queue) == 250 and p.queue.inflight == [] and p.queue.bytes == size
        assert p.tally.written == 0 and p.tally.failed_records == 0
    finally:
        blocker.exec_driver_sql("ROLLBACK")
        blocker.close()
    p.batches.write_pending(lambda: True)
    assert _stored(eng, "d") == list(range(start + 1, start + 251)) and p.tally.batches == 3
    assert p.queue.bytes == 0
    eng.dispose()
    db.dispose()


# --- the lease ---------------------------------------------------------------------------------


def _heartbeat(engine) -> int:
    with engine.connect() as conn:
        beat = conn.exec_driver_sql("SELECT heartbeat_ns FROM hub_lease WHERE hub_id = 'wott-hub'").scalar()
    return int(beat)


def test_the_lease_is_refreshed_when_due_and_a_takeover_is_found_at_the_next_refresh(engine):
    lease = Lease(engine, stale_s=6.0)
    lease.acquire()
    beat = _heartbeat(engine)
    assert lease.next_refresh > time.monotonic()  # every stale_s / 6: not yet
    assert lease.keep() and _heartbeat(engine) == beat
    lease.next_refresh = 0.0
    assert lease.keep() and _heartbeat(engine) > beat and lease.held
    assert lease.next_refresh > time.monotonic()
    with engine.begin() as conn:
        conn.exec_driver_sql(f"UPDATE hub_lease SET holder='usurper', pid=1, host='h', "
                             f"heartbeat_ns={time.time_ns()} WHERE hub_id = 'wott-hub'")
    assert lease.keep()  # not due: nothing asked
    lease.next_refresh = 0.0
    assert not lease.keep() and not lease.held and "taken over" in lease.lost
    assert lease.keep()  # lost already: nothing more to find


def test_a_lease_lost_gives_up_the_queue_counting_and_telling_each_record(engine):
    p = _pieces(engine)
    start = _register(p, "d")
    loop = WriterLoop(p.storage, p.queue, p.tally, p.batches, p.forward, p.storage.state, interval_s=0.01,
                      spill_after_s=2.0, retention=Retention(),
                      retention_clock=RetentionClock(Retention(), engine))
    for r in _recs("d", start, 10):
        p.queue.offer(r)
    loop.keep_lease()  # held, not due
    assert len(p.queue) == 10
    with engine.begin() as conn:
        conn.exec_driver_sql(f"UPDATE hub_lease SET holder='usurper', pid=1, host='h', "
                             f"heartbeat_ns={time.time_ns()} WHERE hub_id = 'wott-hub'")
    p.storage.lease.next_refresh = 0.0
    loop.keep_lease()
    assert len(p.queue) == 0 and p.queue.bytes == 0 and p.tally.dropped == 10
    assert p.tally.failed_seqs == {"d": set(range(start + 1, start + 11))} and p.told == [{"d": start + 10}]
    p.batches.write_pending(lambda: True)  # nothing more is written
    assert _stored(engine, "d") == []


# --- the queue's bounds (issue 48, item 4) -------------------------------------------------------------


def test_the_queue_is_bounded_in_bytes_and_counts_them_back_as_records_leave():
    recs = _recs("d", 0, 20, pad=1_000)
    each = record_bytes(recs[0])
    q = RecordQueue(max_records=1_000, max_bytes=8 * each + each // 2, batch_max=5)
    taken = [r for r in recs if q.offer(r)]
    assert len(taken) == 8 and q.bytes == 8 * each and len(q) == 8
    assert q.wake.is_set()  # a batch is full
    batch = q.take()
    assert [r.seq for r in batch] == [1, 2, 3, 4, 5] and q.bytes == 8 * each and q.inflight == [batch]
    assert not q.offer(recs[8])  # in flight still counts: a failed batch put back stays within the bound
    q.requeue(batch, [batch])  # failed: back at the head
    assert q.bytes == 8 * each and q.inflight == [] and len(q) == 8
    batch = q.take()
    q.requeue(batch[3:], [batch])  # three written, two left: only the written ones leave the count
    assert q.bytes == 5 * each and [q.offer(r) for r in recs[8:12]] == [True] * 3 + [False]
    records = q.drain()
    assert [r.seq for r in records] == list(range(4, 12))
    assert q.bytes == sum(map(record_bytes, records))  # until settled
    q.settle(records)
    assert q.bytes == 0
    small = RecordQueue(max_records=3, max_bytes=1 << 30, batch_max=100)
    assert [small.offer(r) for r in recs[:4]] == [True, True, True, False]  # and in records


def test_records_beyond_the_writers_byte_budget_are_dropped_and_counted_in_health(engine):
    budget = record_bytes(_recs("d", 0, 1, pad=100_000)[0]) * 21 // 2  # ten fit, not eleven
    w = HistoryWriter(engine, interval_s=0.01, queue_max_bytes=budget)
    start = w.register_thing("d")
    for r in _recs("d", start, 25, pad=100_000):  # the writer not started: the database "lags"
        w.submit(r)
    h = w.health()
    assert h["queued"] == 10 and h["dropped"] == 15 and h["queuedBytes"] <= budget
    assert w.failed_seqs == {"d": set(range(start + 11, start + 26))}
    w.start()
    try:
        assert w.flush(60)
    finally:
        w.stop()
    assert w.written == 10 and w.outcome()["lost"] == 15 and w.health()["queuedBytes"] == 0
    assert _stored(engine, "d") == list(range(start + 1, start + 11))


def test_a_queue_over_half_its_byte_budget_goes_to_the_spool_at_once_while_batches_fail(tmp_path, eventually):
    db = create_engine(database_url(tmp_path / "h.db"))
    upgrade(db)
    eng = create_engine(database_url(tmp_path / "h.db"))

    @sa.event.listens_for(eng, "connect")
    def _no_wait(dbapi_conn, _rec):
        dbapi_conn.execute("PRAGMA busy_timeout=20")

    each = record_bytes(_recs("d", 0, 1, pad=50_000)[0])
    w = HistoryWriter(eng, interval_s=0.01, spill_after_s=3_600, queue_max_bytes=20 * each,
                      spool=Spool(tmp_path / "spool", 1 << 26))
    start = w.register_thing("d")
    w.start()
    blocker = db.connect()
    blocker.exec_driver_sql("BEGIN IMMEDIATE")
    try:
        for r in _recs("d", start, 12, pad=50_000):  # over half the budget; spill_after_s is an hour
            w.submit(r)
        eventually(lambda: w.health()["spool"]["records"] == 12, 30, "the queue spooled")
        assert w.health()["queuedBytes"] == 0 and w.dropped == 0
    finally:
        blocker.exec_driver_sql("ROLLBACK")
        blocker.close()
    try:
        eventually(lambda: w.health()["spool"]["records"] == 0, 30, "forwarded")
    finally:
        w.stop()
    assert _stored(db, "d") == list(range(start + 1, start + 13))
    eng.dispose()
    db.dispose()
