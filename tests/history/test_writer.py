"""Batched writer: batches, sequence reservation across clean and crashed runs, retention, export."""

from __future__ import annotations

import io
import json
import time
from collections.abc import Callable

from sqlalchemy.engine import Engine

from wott_hub.events.record import Record
from wott_hub.history import RESERVE, HistoryWriter, Retention, apply_retention, export_jsonl

MakeRecords = Callable[..., list[Record]]  # conftest.make_records


def test_records_are_written_in_batches_and_read_back_in_order(writer, reader, make_records):
    start = writer.register_thing("pad-1", title="Pad", family="scene", td='{"title": "Pad"}')
    assert start == 0
    recs = make_records("pad-1", start, 5000)
    writer.start()
    for r in recs:
        writer.submit(r)
    assert writer.flush()
    assert writer.written == 5000
    assert writer.batches < 100  # batched, not a commit per event
    rows = [row for page in reader.pages("pad-1", page=700) for row in page]
    assert [r.seq for r in rows] == [r.seq for r in recs]
    assert [r.data for r in rows] == [r.data for r in recs]
    (summary,) = reader.things()
    assert (summary.id, summary.count, summary.first_seq, summary.last_seq) == ("pad-1", 5000, 1, 5000)
    assert reader.thing_info("pad-1")["td"] == {"title": "Pad"}


def test_clean_stop_continues_the_sequence_without_a_gap(engine, make_records):
    w = HistoryWriter(engine, interval_s=0.01)
    start = w.register_thing("d")
    w.start()
    for r in make_records("d", start, 100):
        w.submit(r)
    w.stop()
    assert HistoryWriter(engine).register_thing("d") == 100


def test_after_a_crash_the_sequence_continues_above_every_number_handed_out(engine, make_records):
    w = HistoryWriter(engine, interval_s=0.01)
    start = w.register_thing("d")
    recs = make_records("d", start, 300)
    w.start()
    for r in recs[:200]:
        w.submit(r)
    assert w.flush()
    # the process dies here: records 201..300 were handed out (seen by clients), never committed;
    # no stop(), so nothing is released
    w._stop = True
    w._wake.set()
    restart = HistoryWriter(engine).register_thing("d")
    assert restart >= 300  # continues above the reservation: a gap, never a reuse
    assert restart == RESERVE  # reserved when the Thing registered, before its first record
    from wott_hub.history import HistoryReader

    assert [row.seq for p in HistoryReader(engine).pages("d") for row in p] == list(range(1, 201))


def test_resume_rows_filter_by_interest_and_report_progress(writer, reader, make_records):
    start = writer.register_thing("d")
    writer.start()
    for r in make_records("d", start, 50):
        writer.submit(r)
    writer.flush()
    recs, reached = reader.rows("d", 10, 40, (0, "skinDeformedDetection"), limit=1000)
    assert [r.seq for r in recs] == list(range(11, 41, 2))
    assert reached == 40
    recs, reached = reader.rows("d", 10, 40, (1, None), limit=5)
    assert reached == 15 and [r.seq for r in recs] == [12, 14]


def test_time_range_export_is_json_lines_with_payloads_as_recorded(writer, reader, make_records):
    start = writer.register_thing("d")
    recs = make_records("d", start, 40)
    writer.start()
    for r in recs:
        writer.submit(r)
    writer.flush()
    t_from, t_to = recs[10].t_ns, recs[29].t_ns
    out = io.StringIO()
    n = export_jsonl(reader, out, "d", t_from_ns=t_from, t_to_ns=t_to)
    lines = [json.loads(line) for line in out.getvalue().splitlines()]
    expected = [r for r in recs if t_from <= r.t_ns <= t_to]
    assert n == len(lines) == len(expected)
    assert [line["seq"] for line in lines] == [r.seq for r in expected]
    assert [line["data"] for line in lines] == [json.loads(r.data) for r in expected]
    assert {line["kind"] for line in lines} == {"event", "property"}
    out = io.StringIO()
    export_jsonl(reader, out, "d", names=["contactInformation"])
    assert {json.loads(x)["name"] for x in out.getvalue().splitlines()} == {"contactInformation"}


def test_retention_by_age_deletes_only_old_events(writer, reader, engine, make_records):
    start = writer.register_thing("d")
    day = 86_400 * 10**9
    old = make_records("d", start, 10, t0_ns=10**18)
    new = make_records("d", start + 10, 10, t0_ns=10**18 + 5 * day)
    writer.start()
    for r in old + new:
        writer.submit(r)
    writer.flush()
    deleted = apply_retention(engine, Retention(days=2), now_ns=10**18 + 6 * day)
    assert deleted == 10
    assert [row.seq for p in reader.pages("d") for row in p] == [r.seq for r in new]


def test_retention_by_size_keeps_the_newest_data_under_the_limit(writer, reader, engine, make_records):
    from wott_hub.history.retention import used_bytes

    start = writer.register_thing("d")
    recs = make_records("d", start, 20_000)
    writer.start()
    for r in recs:
        writer.submit(r)
    writer.flush()
    with engine.connect() as conn:
        before = used_bytes(conn)
    limit_mb = before / 2 / 1e6
    assert apply_retention(engine, Retention(max_mb=limit_mb)) > 0
    with engine.connect() as conn:
        assert used_bytes(conn) <= limit_mb * 1e6
    seqs = [row.seq for p in reader.pages("d") for row in p]
    assert seqs and seqs[-1] == recs[-1].seq  # the newest survive
    assert seqs == list(range(seqs[0], recs[-1].seq + 1))  # a contiguous newest range


def test_a_refused_row_is_isolated_and_the_rest_written_on_either_engine(writer, reader, engine,
                                                                        make_records):
    """PostgreSQL writes batches with COPY: one refused row fails the COPY, and the batch is
    halved down to it exactly as an INSERT's would be."""
    from wott_hub.history import EventRow

    start = writer.register_thing("d")
    recs = make_records("d", start, 100)
    with engine.begin() as conn:  # seq 50 is already there (a second writer of the same Thing)
        conn.execute(EventRow.__table__.insert().values(thing_key=writer.storage.keys["d"], seq=recs[49].seq,
                                                        t_ns=recs[49].t_ns, kind=0, name="other", data=b"{}"))
    writer.start()
    for r in recs:
        writer.submit(r)
    assert writer.flush()
    assert (writer.written, writer.failed_records) == (99, 1)
    assert "seq 50 not recorded" in writer.last_error
    rows = {row.seq: row for page in reader.pages("d") for row in page}
    assert sorted(rows) == [r.seq for r in recs]
    assert rows[50].name == "other" and all(rows[r.seq].data == r.data for r in recs if r.seq != 50)


def _stored(engine: Engine) -> list[tuple[int, str, bytes]]:
    with engine.connect() as conn:
        return [(seq, name, bytes(data)) for seq, name, data in
                conn.exec_driver_sql("SELECT seq, name, data FROM events ORDER BY seq")]


def test_batches_written_while_the_next_is_encoded_store_every_byte(engine: Engine,
                                                                     make_records: MakeRecords) -> None:
    """A writer behind (many batches waiting): on PostgreSQL the next batch is encoded while the
    server takes this one's COPY data (built by the writer itself). Each record's stored bytes
    are exactly codec.encode_records' (names and payloads beyond ASCII too), commits in order."""
    from wott_hub.events.record import KIND_PROPERTY
    from wott_hub.history.codec import encode_records

    tops: list[dict[str, int]] = []
    w = HistoryWriter(engine, interval_s=0.01, batch_max=500, on_commit=tops.append)
    try:
        start = w.register_thing("d")
        recs = make_records("d", start, 6000)
        recs[4321] = Record("d", recs[4321].seq, KIND_PROPERTY, "größe-ü", recs[4321].t_ns, '{"é": "ß"}')
        recs[17] = Record("d", recs[17].seq, KIND_PROPERTY, "empty", recs[17].t_ns, "")
        for r in recs:  # all waiting before the writer starts: it runs behind from the first batch
            w.submit(r)
        w.start()
        assert w.flush()
    finally:
        w.stop()
    assert (w.written, w.failed_records, w.errors) == (6000, 0, 0)
    assert _stored(engine) == [(r.seq, r.name, d) for r, d in zip(recs, encode_records(recs), strict=True)]
    seqs = [t["d"] for t in tops]
    assert seqs == sorted(set(seqs)) and seqs[-1] == recs[-1].seq  # watermarks only move forward


def test_a_failed_batch_and_the_one_taken_after_it_are_retried_in_order(engine: Engine,
                                                                         make_records: MakeRecords) -> None:
    """A failure that is not about the rows (here the table is missing for a while) puts the
    batch and the one already taken to be encoded back at the head of the queue, in order."""
    tops: list[dict[str, int]] = []
    w = HistoryWriter(engine, interval_s=0.01, batch_max=500, on_commit=tops.append)
    try:
        start = w.register_thing("d")
        recs = make_records("d", start, 4000)
        with engine.begin() as conn:
            conn.exec_driver_sql("ALTER TABLE events RENAME TO events_away")
        for r in recs:
            w.submit(r)
        w.start()
        deadline = time.monotonic() + 10
        while w.errors == 0 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert w.errors >= 1 and w.written == 0 and w.queue_depth + w.written <= 4000
        with engine.begin() as conn:
            conn.exec_driver_sql("ALTER TABLE events_away RENAME TO events")
        assert w.flush()
    finally:
        w.stop()
    assert (w.written, w.failed_records, w.dropped) == (4000, 0, 0)
    assert [s for s, _, _ in _stored(engine)] == [r.seq for r in recs]
    seqs = [t["d"] for t in tops]
    assert seqs == sorted(set(seqs)) and seqs[-1] == recs[-1].seq


def test_a_number_the_database_cannot_store_is_isolated_not_retried_forever(database: str,
                                                                           make_records: MakeRecords) -> None:
    """A value beyond its column (int8 t_ns) is the row's DataError, isolated like a row the
    database refuses: PostgreSQL's COPY data is built by the writer, SQLite's driver raises
    OverflowError when it binds the value; neither is retried forever."""
    from wott_hub.history import create_engine, upgrade

    engine = create_engine(database)
    upgrade(engine)
    w = HistoryWriter(engine, interval_s=0.01)
    try:
        start = w.register_thing("d")
        recs = make_records("d", start, 40)
        bad = recs[21]
        recs[21] = Record("d", bad.seq, bad.kind, bad.name, 1 << 63, bad.data)
        w.start()
        for r in recs:
            w.submit(r)
        assert w.flush()
    finally:
        w.stop()
    try:
        assert (w.written, w.failed_records) == (39, 1)
        assert f"seq {bad.seq} not recorded" in w.last_error and "out of range" in w.last_error
        assert [s for s, _, _ in _stored(engine)] == [r.seq for r in recs if r is not recs[21]]
    finally:
        engine.dispose()
