"""Replay: the recorded payloads, in order, at the requested pace (functional tolerance, not a benchmark)."""

from __future__ import annotations

import asyncio

import pytest

from wott_hub.history import Replayer


@pytest.fixture
def recorded(writer, make_records):
    start = writer.register_thing("d")
    recs = make_records("d", start, 240)  # 1 s of a 120 Hz device (event + property per frame)
    writer.start()
    for r in recs:
        writer.submit(r)
    assert writer.flush()
    return recs


def test_replay_reproduces_payloads_in_order_at_the_requested_speed(reader, recorded):
    """In order, never ahead of the original timing scaled by ``speed``, and faster than the
    original: the bounds a busy machine cannot break (it only makes a replay later) and a replay
    that ignored ``speed`` (1 s of records in 1 s, not 0.25 s) does. How close to the scaled time
    each record comes is a timing, not asserted here."""
    got = []
    speed = 4.0

    async def main():
        loop = asyncio.get_running_loop()
        await Replayer(reader, "d", speed=speed, page=50).run(
            lambda r: got.append((loop.time(), r.kind, r.name, r.data)))

    asyncio.run(main())
    assert [(k, n, d) for _, k, n, d in got] == [(r.kind, r.name, r.data) for r in recorded]
    t0 = got[0][0]
    due = [(r.t_ns - recorded[0].t_ns) / 1e9 / speed for r in recorded]
    late = [(t - t0) - d for (t, *_), d in zip(got, due, strict=True)]
    assert min(late) > -0.003  # never ahead of the scaled original timing
    original = (recorded[-1].t_ns - recorded[0].t_ns) / 1e9
    assert got[-1][0] - t0 < original  # paced by speed: in less than the recording's own time


def test_a_time_range_replays_only_that_range(reader, recorded):
    lo, hi = recorded[100].t_ns, recorded[139].t_ns
    rp = Replayer(reader, "d", t_from_ns=lo, t_to_ns=hi, speed=0)
    got = []
    asyncio.run(rp.run(lambda r: got.append(r.data)))
    assert got == [r.data for r in recorded if lo <= r.t_ns <= hi]


def test_speed_zero_replays_everything_without_waiting(reader, recorded):
    rp = Replayer(reader, "d", speed=0)
    got = []
    asyncio.run(rp.run(lambda r: got.append(r.data)))
    assert got == [r.data for r in recorded] and rp.cycles == 1


def test_loop_starts_again_after_the_end(reader, recorded):
    rp = Replayer(reader, "d", speed=8.0, loop=True)  # a cycle lasts ~0.125 s
    got = []
    n = len(recorded)

    async def main():
        stop = asyncio.Event()

        def take(r) -> None:  # stopped once the third cycle has begun: counted, not timed
            got.append(r.data)
            if len(got) > 2 * n:
                stop.set()

        await rp.run(take, stop)

    asyncio.run(main())
    assert rp.cycles >= 2
    assert got[:n] == [r.data for r in recorded] and got[n:2 * n] == [r.data for r in recorded]


def test_negative_speed_is_refused(reader):
    with pytest.raises(ValueError):
        Replayer(reader, "d", speed=-1)


@pytest.mark.parametrize("database", ["sqlite"], indirect=True)  # the joined page is SQLite's
def test_pages_sqlite_cannot_join_are_read_row_by_row(database, engine, reader, recorded):
    """On SQLite a page is read as one joined row (``reader._JOINED``); a page longer than SQLite's
    longest value, or holding a non-ASCII payload stored as text (before revision 0006; its
    ``length`` counts characters), is read row by row: the same records either way."""
    import sqlite3

    import sqlalchemy as sa

    from wott_hub.history import HistoryReader, create_engine

    assert engine.dialect.name == "sqlite"
    with engine.begin() as conn:  # payloads as text, as revision 0005 stored them
        conn.execute(sa.text("UPDATE events SET data = CAST(data AS TEXT) WHERE seq = :s"),
                     {"s": recorded[51].seq})
        conn.execute(sa.text("UPDATE events SET data = :d WHERE seq = :s"),
                     {"d": '{"note":"é"}', "s": recorded[153].seq})
    want = [(r.kind, r.name, '{"note":"é"}' if i == 153 else r.data) for i, r in enumerate(recorded)]
    short = create_engine(database)
    sa.event.listen(short, "connect", lambda dbapi, _: dbapi.setlimit(sqlite3.SQLITE_LIMIT_LENGTH, 4000))
    try:
        for rd in (reader, HistoryReader(short)):
            got: list[tuple[int, str, str]] = []
            emit = lambda r, got=got: got.append((r.kind, r.name, r.data))  # noqa: E731
            asyncio.run(Replayer(rd, "d", speed=0, page=40).run(emit))
            assert got == want
    finally:
        short.dispose()
