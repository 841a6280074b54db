"""The history spool (``history/spool.py``) and the writer's store and forward (``writer.py``), on real
files: order, bounds, torn frames, a second process refused; records that cannot reach a real SQLite
database (its write lock held by another connection) go to the spool and are written, in order and
once, when it answers again or by the next writer."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest
import sqlalchemy as sa

from wott_hub.errors import Conflict
from wott_hub.events.record import KIND_EVENT, Record
from wott_hub.history import HistoryReader, HistoryWriter, create_engine, database_url, upgrade
from wott_hub.history.spool import FRAME_RECORDS, MAGIC, Spool


def _rows(thing: str, first: int, n: int, size: int = 10) -> list[tuple[str, int, int, str, int, bytes]]:
    return [(thing, s, KIND_EVENT, "tick", 10**18 + s, b"x" * size) for s in range(first, first + n)]


def _recs(thing: str, after: int, n: int) -> list[Record]:
    return [Record(thing, after + i + 1, KIND_EVENT, "tick", 10**18 + after + i,
                   json.dumps({"i": after + i + 1})) for i in range(n)]


def test_rows_come_back_in_order_across_segments_and_a_reopen(tmp_path):
    sp = Spool(tmp_path / "s", 1 << 22, segment_bytes=1 << 12)
    sp.open()
    for i in range(20):
        sp.append(_rows("a", i * 50 + 1, 50))
    assert sp.records == 1000 and sp.max_seq == {"a": 1000} and sp.oldest_t_ns == 10**18 + 1
    sp.close()
    again = Spool(tmp_path / "s", 1 << 22, segment_bytes=1 << 12)
    again.open()  # what a previous run left
    assert again.records == 1000 and again.max_seq == {"a": 1000}
    seqs = []
    while (head := again.head()) is not None:
        seg, rows = head
        seqs += [r[1] for r in rows]
        again.consumed(seg)
    assert seqs == list(range(1, 1001)) and again.records == 0
    again.close()


def test_a_frame_torn_by_a_crash_ends_the_segment_and_keeps_what_came_before(tmp_path):
    sp = Spool(tmp_path / "s", 1 << 22)
    sp.open()
    sp.append(_rows("a", 1, 10))
    sp.append(_rows("a", 11, 10))
    sp.close()
    seg = next((tmp_path / "s").glob("*.seg"))
    data = seg.read_bytes()
    seg.write_bytes(data[:-7])  # the last frame half written
    again = Spool(tmp_path / "s", 1 << 22)
    again.open()
    assert again.records == 10
    _, rows = again.head()
    assert [r[1] for r in rows] == list(range(1, 11))
    again.append(_rows("a", 21, 5))  # a new segment: nothing is appended after a torn frame
    assert again.records == 15
    again.close()


def test_the_spool_is_bounded_and_drops_its_oldest_segments_counting_them(tmp_path):
    sp = Spool(tmp_path / "s", 1 << 16, segment_bytes=1 << 13)  # 64 KiB, 8 KiB segments
    sp.open()
    for i in range(100):
        sp.append(_rows("a", i * 10 + 1, 10, size=200))  # ~2 KB a frame: ~200 KB in all
    assert sp.bytes <= 1 << 16 and sp.dropped > 0
    assert sp.records + sp.dropped == 1000
    seqs = []
    while (head := sp.head()) is not None:
        seqs += [r[1] for r in head[1]]
        sp.consumed(head[0])
    assert seqs == list(range(1001 - len(seqs), 1001))  # the newest kept, in order, none twice
    sp.close()


def test_a_second_process_cannot_take_the_same_spool(tmp_path):
    sp = Spool(tmp_path / "s", 1 << 20)
    sp.open()
    assert not (tmp_path / "s").exists()  # nothing waits: no folder until something must
    sp.append(_rows("a", 1, 1))
    code = textwrap.dedent(f"""
        from wott_hub.history.spool import Spool
        from wott_hub.errors import Conflict
        try:
            Spool({str(tmp_path / "s")!r}, 1 << 20).open()
        except Conflict as e:
            print("refused:", e)
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.stdout.startswith("refused:") and "in use by another process" in out.stdout, out.stderr
    sp.close()
    with pytest.raises(Conflict):  # two writers of one process: refused as well (one spool, one writer)
        sp.open()
        Spool(tmp_path / "s", 1 << 20).open()
    sp.close()


@pytest.fixture
def db(tmp_path):
    eng = create_engine(database_url(tmp_path / "h.db"))
    upgrade(eng)
    yield eng
    eng.dispose()


def _impatient(db) -> sa.Engine:
    eng = create_engine(database_url(db.url.database))

    @sa.event.listens_for(eng, "connect")
    def _no_wait(dbapi_conn, _rec):  # after the hub's pragmas: a held lock fails a batch at once
        dbapi_conn.execute("PRAGMA busy_timeout=20")

    return eng


def _stored(db, thing: str) -> list[int]:
    """The thing's seqs in the order their rows were inserted (the table's id)."""
    with db.connect() as conn:
        return list(conn.execute(sa.text("SELECT e.seq FROM events e JOIN things t ON t.key = e.thing_key "
                                          "WHERE t.id = :t ORDER BY e.id"), {"t": thing}).scalars())


def test_an_outage_spools_and_the_records_are_forwarded_in_order_once_it_ends(db, tmp_path, eventually):
    eng = _impatient(db)
    tops: list[dict[str, int]] = []
    w = HistoryWriter(eng, interval_s=0.01, spill_after_s=0.2, on_commit=tops.append,
                      spool=Spool(tmp_path / "spool", 1 << 24))
    start = w.register_thing("d")
    w.start()
    blocker = db.connect()
    try:
        for r in _recs("d", start, 100):
            w.submit(r)
        assert w.flush(10)
        blocker.exec_driver_sql("BEGIN IMMEDIATE")  # the database cannot take a batch now
        for r in _recs("d", start + 100, 300):
            w.submit(r)
        h = eventually(lambda: (h := w.health())["spool"]["records"] == 300 and h, 15, "the queue spooled")
        assert h["state"] == "degraded" and h["queued"] == 0 and h["spool"]["oldestAgeS"] >= 0
        assert max(t.get("d", 0) for t in tops) == start + 400  # spooled = durable: subscribers may see it
        assert HistoryReader(eng).failure.startswith("300 records wait in the spool")  # resumes wait
        for r in _recs("d", start + 400, 50):  # more while it lasts: behind the spooled ones
            w.submit(r)
        blocker.exec_driver_sql("ROLLBACK")
        eventually(lambda: w.health()["spool"]["records"] == 0 and w.queue_depth == 0, 20, "forwarded")
        assert w.flush(10) and w.health()["state"] == "ok"
        assert w.written == 450 and w.forwarded >= 300
    finally:
        blocker.close()
        w.stop()
        eng.dispose()
    assert _stored(db, "d") == list(range(start + 1, start + 451))  # in order, each once


def test_a_stop_during_an_outage_spools_and_the_next_writer_forwards_without_duplicates(db, tmp_path):
    eng = _impatient(db)
    w = HistoryWriter(eng, interval_s=0.01, spill_after_s=60, spool=Spool(tmp_path / "spool", 1 << 24))
    start = w.register_thing("d")
    w.start()
    blocker = db.connect()
    blocker.exec_driver_sql("BEGIN IMMEDIATE")
    try:
        for r in _recs("d", start, 200):
            w.submit(r)
        w.stop(timeout_s=5)  # failing at stop: to the spool at once, not after spill_after_s
        assert w.outcome() == {"written": 0, "spooled": 200, "lost": 0}
    finally:
        blocker.exec_driver_sql("ROLLBACK")
        blocker.close()
        eng.dispose()
    # a crash after a batch of the spool was committed but before its segment went: written again
    with db.begin() as conn:
        key = conn.execute(sa.text("SELECT key FROM things WHERE id = 'd'")).scalar()
        for s in range(start + 1, start + 51):
            conn.execute(sa.text("INSERT INTO events (thing_key, seq, t_ns, kind, name, data) VALUES "
                                 "(:k, :s, :t, 0, 'tick', :d)"),
                         {"k": key, "s": s, "t": 10**18 + s - 1, "d": json.dumps({"i": s}).encode()})
    nxt = HistoryWriter(db, interval_s=0.01, spool=Spool(tmp_path / "spool", 1 << 24))
    again = nxt.register_thing("d")
    assert again >= start + 200  # the spooled seqs are never handed out again
    nxt.start()
    for r in _recs("d", again, 10):
        nxt.submit(r)
    assert nxt.flush(20)
    nxt.stop()
    assert _stored(db, "d") == list(range(start + 1, start + 201)) + list(range(again + 1, again + 11))
    assert nxt.forwarded == 150 and nxt.written == 10  # this run's own records; the spool's are counted apart


def test_a_writer_stuck_in_the_database_is_left_behind_and_its_batch_spooled(db, tmp_path):
    w = HistoryWriter(db, interval_s=0.01, spool=Spool(tmp_path / "spool", 1 << 24))  # 10 s busy timeout
    start = w.register_thing("d")
    w.start()
    blocker = db.connect()
    blocker.exec_driver_sql("BEGIN IMMEDIATE")  # the writer's next batch waits for the lock for 10 s
    try:
        for r in _recs("d", start, 50):
            w.submit(r)
        import time

        t0 = time.monotonic()
        w.hurry()  # a second Ctrl-C
        w.stop(timeout_s=30)
        took = time.monotonic() - t0
        assert took < 5, f"stop took {took:.1f} s"
        assert w.outcome()["spooled"] == 50 and w.outcome()["lost"] == 0
    finally:
        blocker.exec_driver_sql("ROLLBACK")
        blocker.close()


# --- issue 48: what lies in the spool folder (items 2, 3, 5) ------------------------------------------------

def _spool_of(tmp_path, n: int = 2000) -> Spool:
    sp = Spool(tmp_path / "s", 1 << 24)
    sp.open()
    sp.append(_rows("a", 1, n, size=50))  # one append: frames of at most FRAME_RECORDS records
    sp.close()
    return sp


def _drain(sp: Spool) -> list[int]:
    seqs = []
    while (head := sp.head()) is not None:
        seqs += [r[1] for r in head[1]]
        sp.consumed(head[0])
    return seqs


def test_one_flipped_byte_costs_one_frame_named_with_its_count_and_the_segment_is_kept(tmp_path):
    _spool_of(tmp_path)
    seg = next((tmp_path / "s").glob("*.seg"))
    data = bytearray(seg.read_bytes())
    data[len(data) // 2] ^= 0x01
    seg.write_bytes(bytes(data))
    sp = Spool(tmp_path / "s", 1 << 24)
    sp.open()
    [d] = sp.damage()
    assert 0 < d["records"] <= FRAME_RECORDS and not d["estimated"] and d["bytes"] > 0
    assert sp.records + d["records"] == 2000  # what was read and what was lost: the whole
    seqs = _drain(sp)
    assert seqs == sorted(seqs) and len(seqs) == 2000 - d["records"]
    assert not list((tmp_path / "s").glob("*.seg")) and (tmp_path / "s" / (seg.name + ".damaged")).exists()
    assert sp.damage() == [d]  # still there: still named, until someone deletes it
    (tmp_path / "s" / (seg.name + ".damaged")).unlink()
    assert sp.damage() == []
    sp.close()


def test_a_broken_header_or_frame_header_loses_no_more_than_its_frame(tmp_path):
    _spool_of(tmp_path)
    seg = next((tmp_path / "s").glob("*.seg"))
    data = bytearray(seg.read_bytes())
    data[1] ^= 0xFF  # the segment's MAGIC
    data[len(MAGIC) + 2] ^= 0xFF  # the first frame's header: found again by the next sync mark
    seg.write_bytes(bytes(data))
    sp = Spool(tmp_path / "s", 1 << 24)
    sp.open()
    [d] = sp.damage()
    assert d["estimated"] and 0 < d["records"] <= 2 * FRAME_RECORDS, d
    assert 2000 - FRAME_RECORDS <= sp.records < 2000
    assert "header" in d["reason"]
    sp.close()


def test_segments_that_are_not_regular_files_are_set_aside_unread(tmp_path):
    import os

    folder = tmp_path / "s"
    folder.mkdir()
    os.mkfifo(folder / "0000000000.seg")  # opening it blocking would wait for a writer for ever
    (folder / "0000000001.seg").symlink_to("/dev/zero")  # reading it would never end
    os.mkfifo(folder / "lock")
    sp = Spool(folder, 1 << 20)
    sp.open()
    assert sp.records == 0
    kept = sorted(p.name for p in folder.iterdir())
    assert kept == ["0000000000.seg.notfile", "0000000001.seg.notfile", "lock", "lock.notfile"], kept
    assert [d["reason"] for d in sp.damage()] == ["not a regular file (a FIFO)",
                                                 "not a regular file (a FIFO)",
                                                 "not a regular file (a symbolic link)"]
    sp.append(_rows("a", 1, 3))  # numbered after what was set aside
    assert sorted(p.name for p in folder.glob("*.seg")) == ["0000000002.seg"]
    sp.close()


def test_a_segment_larger_than_the_spool_is_not_read(tmp_path):
    folder = tmp_path / "s"
    folder.mkdir()
    with (folder / "0000000001.seg").open("wb") as f:
        f.truncate(2 << 20)  # sparse: 2 MB of zeros, beyond a 1 MB spool
    sp = Spool(folder, 1 << 20)
    sp.open()
    [d] = sp.damage()
    assert "larger than the spool's bound" in d["reason"] and sp.records == 0
    sp.close()


def test_a_spool_file_of_zeros_is_passed_over_at_once(tmp_path):
    import time

    folder = tmp_path / "s"
    folder.mkdir()
    with (folder / "0000000001.seg").open("wb") as f:
        f.truncate(64 << 20)  # sparse: 64 MB of zeros, within the spool's bound, no frame in it
    sp = Spool(folder, 256 << 20)
    t0 = time.monotonic()
    sp.open()
    took = time.monotonic() - t0
    [d] = sp.damage()
    assert sp.records == 0 and d["bytes"] >= (64 << 20) - 64 and "header" in d["reason"]
    assert took < 30, f"{took:.1f} s to pass over 64 MB of zeros"  # generous: a scan, not a frame loop
    sp.close()
