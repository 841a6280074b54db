"""Batched writer: batches, sequence reservation across clean and crashed runs, retention, export."""

from __future__ import annotations

import io
import json

from wott_hub.history import RESERVE, HistoryWriter, Retention, apply_retention, export_jsonl


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
    assert [r[0] for r in rows] == [r.seq for r in recs]
    assert [r[4] for r in rows] == [r.data for r in recs]
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

    assert [row[0] for p in HistoryReader(engine).pages("d") for row in p] == list(range(1, 201))


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
    assert [row[0] for p in reader.pages("d") for row in p] == [r.seq for r in new]


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
    seqs = [row[0] for p in reader.pages("d") for row in p]
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
        conn.execute(EventRow.__table__.insert().values(thing_key=writer.keys["d"], seq=recs[49].seq,
                                                        t_ns=recs[49].t_ns, kind=0, name="other", data=b"{}"))
    writer.start()
    for r in recs:
        writer.submit(r)
    assert writer.flush()
    assert (writer.written, writer.failed_records) == (99, 1)
    assert "seq 50 not recorded" in writer.last_error
    rows = {row[0]: row for page in reader.pages("d") for row in page}
    assert sorted(rows) == [r.seq for r in recs]
    assert rows[50][3] == "other" and all(rows[r.seq][4] == r.data for r in recs if r.seq != 50)
