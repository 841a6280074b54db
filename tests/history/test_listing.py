"""Issue 32 item 4: what ``history list`` reads (``HistoryReader.things``), on SQLite and PostgreSQL.

The listing takes each Thing's first and last seq and time from the ends of its indexes in one
statement; the exact record count is asked for separately (``count=True``: a scan). Both must give
the same ends, with a gap in the seqs, after a range of the oldest is deleted, and for a Thing
registered with nothing recorded yet. How fast it is: ``wott-hub bench history_list``.
"""

from __future__ import annotations

import sqlalchemy as sa

from wott_hub.events.record import KIND_EVENT, Record
from wott_hub.history.models import EventRow


def test_the_ends_come_from_the_indexes_and_the_count_on_request(engine, writer, reader, make_records):
    a = writer.register_thing("a", family="flat-vision")
    b = writer.register_thing("b", family="taxel-array")
    writer.register_thing("idle", family="scene")
    writer.start()
    recs_a = make_records("a", a, 600, t0_ns=2 * 10**18)
    recs_b = make_records("b", b, 250, t0_ns=10**18)
    for r in [*recs_a, *recs_b]:
        writer.submit(r)
    assert writer.flush(30)
    with engine.begin() as conn:  # a gap (a crash's lost records), and the oldest deleted (retention)
        e = EventRow.__table__
        key = conn.execute(sa.text("SELECT key FROM things WHERE id = 'a'")).scalar_one()
        conn.execute(e.delete().where(e.c.thing_key == key, e.c.seq.between(a + 101, a + 150)))
        conn.execute(e.delete().where(e.c.thing_key == key, e.c.seq <= a + 10))
    fast = {t.id: t for t in reader.things(count=False)}
    exact = {t.id: t for t in reader.things(count=True)}
    assert list(fast) == ["a", "b", "idle"] == list(exact)
    kept_a = [r for r in recs_a if not (a + 101 <= r.seq <= a + 150 or r.seq <= a + 10)]
    for things in (fast, exact):
        assert (things["a"].first_seq, things["a"].last_seq) == (kept_a[0].seq, kept_a[-1].seq)
        assert (things["a"].first_t_ns, things["a"].last_t_ns) == (kept_a[0].t_ns, kept_a[-1].t_ns)
        assert (things["b"].first_seq, things["b"].last_seq) == (recs_b[0].seq, recs_b[-1].seq)
        assert (things["b"].first_t_ns, things["b"].last_t_ns) == (recs_b[0].t_ns, recs_b[-1].t_ns)
        assert things["a"].family == "flat-vision" and things["b"].family == "taxel-array"
        idle = things["idle"]
        assert (idle.count, idle.first_seq, idle.last_seq, idle.first_t_ns, idle.last_t_ns) == (0, None, None,
                                                                                               None, None)
    assert fast["a"].count is None and fast["b"].count is None  # not counted unless asked
    assert exact["a"].count == len(kept_a) and exact["b"].count == len(recs_b)


def test_the_first_page_of_a_range_is_small_and_the_rest_follow_in_order(writer, reader, make_records):
    from wott_hub.history.reader import FIRST_PAGE

    start = writer.register_thing("d")
    writer.start()
    recs = make_records("d", start, FIRST_PAGE * 3 + 7)
    for r in recs:
        writer.submit(r)
    assert writer.flush(30)
    pages = list(reader.pages("d", page=FIRST_PAGE * 2))
    assert [len(p) for p in pages] == [FIRST_PAGE, FIRST_PAGE * 2, 7]
    assert [r.seq for p in pages for r in p] == [r.seq for r in recs]


def test_a_record_stamped_before_its_predecessor_is_read_without_bounds(writer, reader, make_records):
    """A raw image is published once encoded, stamped with its frame's time: after records of later
    frames. The reader's seq range once came from the earliest and latest time, and left it out."""
    start = writer.register_thing("cam")
    writer.start()
    recs = make_records("cam", start, 4)
    late = Record("cam", start + 5, KIND_EVENT, "rawImageRecorded", recs[0].t_ns + 1, '{"camera":"camera"}')
    for r in [*recs, late]:
        writer.submit(r)
    assert writer.flush(30)
    assert [r.seq for r in reader.record_page("cam")] == [*(r.seq for r in recs), late.seq]
    assert [r.seq for r in reader.record_page("cam", names=["rawImageRecorded"])] == [late.seq]
    assert [r.seq for p in reader.pages("cam") for r in p] == [*(r.seq for r in recs), late.seq]
    assert reader.seq_range("cam") == (recs[0].seq, late.seq)
