"""The writer's batches written by a process of their own (``history/batch_process.py``).

The same rows as the writer's own thread writes, byte for byte, on SQLite and PostgreSQL; rows
the database refuses isolated as in the thread; a process that is killed costs a retry, not a
record; a process whose writer dies (SIGKILL) ends by itself.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import sqlalchemy as sa

from wott_hub.events.record import KIND_EVENT, Record, SkinArrays
from wott_hub.history import HistoryWriter, create_engine, database_url, upgrade

from .skin_records import register_device, skin_records


def _with_arrays(recs: list[Record]) -> list[Record]:
    """Every other skin packet carries the arrays the pipeline made it from (the rest: text only)."""
    out = []
    for i, r in enumerate(recs):
        if r.name == "skinDeformedDetection" and i % 2 == 0:
            nodes = json.loads(r.data)["arrayOfDeformedNodes"]
            skin = SkinArrays(np.array([n["deformedNodeID"] for n in nodes]),
                              np.array([n["deformedNodeIntensity"] for n in nodes]))
            r = Record(r.thing, r.seq, r.kind, r.name, r.t_ns, r.data, None, skin)
        out.append(r)
    return out


def _rows(engine) -> list[tuple]:
    with engine.connect() as conn:
        return [tuple(r) for r in conn.execute(sa.text(
            "SELECT e.seq, e.t_ns, e.kind, e.name, e.data, t.seq_reserved FROM events e "
            "JOIN things t ON t.key = e.thing_key ORDER BY e.seq"))]


def test_the_process_writes_the_rows_the_thread_writes(engine, tmp_path):
    """``engine``: SQLite, then PostgreSQL (COPY in the process); the thread's copy is on SQLite."""
    rows = {}
    for process, eng in ((True, engine), (False, create_engine(database_url(tmp_path / "thread.db")))):
        upgrade(eng)
        w = HistoryWriter(eng, interval_s=0.01, process=process)
        start, n_nodes = register_device(w, "pad")
        w.start()
        recs = _with_arrays(skin_records("pad", start, 600, n_nodes))
        for r in recs:
            w.submit(r)
        assert w.flush(30)
        w.stop()
        assert (w.written, w.errors, w.failed_records) == (len(recs), 0, 0)
        rows[process] = [(seq - start, *rest) for seq, *rest in _rows(eng)]
    assert rows[True] == rows[False]
    assert sum(bytes(r[4])[:1] == b"\x01" for r in rows[True]) == 600  # every skin packet packed


def test_rows_the_database_refuses_are_isolated_as_in_the_thread(tmp_path):
    engine = create_engine(database_url(tmp_path / "h.db"))
    upgrade(engine)
    w = HistoryWriter(engine, interval_s=0.01, process=True)
    start = w.register_thing("d")
    with engine.begin() as conn:  # a row already there with a seq this writer is about to write
        conn.exec_driver_sql("INSERT INTO events (thing_key, seq, t_ns, kind, name, data) "
                             f"VALUES ({w.storage.keys['d']}, {start + 7}, 1, 0, 'tick', '\"theirs\"')")
    w.start()
    try:
        for i in range(1, 21):
            w.submit(Record("d", start + i, KIND_EVENT, "tick", 10**18 + i, json.dumps(i)))
        assert w.flush(30)
        assert (w.written, w.failed_records) == (19, 1)
        assert w.failed_seqs["d"] == {start + 7}
        assert "UNIQUE" in w.health()["lastError"]
    finally:
        w.stop()
    with engine.connect() as conn:
        assert conn.exec_driver_sql("SELECT count(*) FROM events").scalar() == 20


def test_a_killed_process_costs_a_retry_and_no_record(tmp_path, caplog):
    engine = create_engine(database_url(tmp_path / "h.db"))
    upgrade(engine)
    w = HistoryWriter(engine, interval_s=0.01, process=True)
    start = w.register_thing("d")
    w.start()
    try:
        w.submit(Record("d", start + 1, KIND_EVENT, "tick", 10**18, "1"))
        assert w.flush(30)
        pid = w._process.pid
        os.kill(pid, signal.SIGKILL)
        for i in range(2, 101):
            w.submit(Record("d", start + i, KIND_EVENT, "tick", 10**18 + i, str(i)))
        assert w.flush(30)
        assert w.written == 100 and w.errors >= 1 and w._process.pid != pid
        assert "the history process exited" in caplog.text
        assert w.health()["state"] == "ok"
    finally:
        w.stop()
    with engine.connect() as conn:
        assert [r[0] for r in conn.exec_driver_sql("SELECT seq FROM events ORDER BY seq")] == \
            list(range(start + 1, start + 101))


def test_the_process_ends_when_its_writer_is_killed(tmp_path):
    """The hub SIGKILLed: the process, in a session of its own, sees its input close and exits."""
    script = textwrap.dedent(f"""
        import sys, time
        from wott_hub.events.record import Record
        from wott_hub.history import HistoryWriter, create_engine, database_url, upgrade
        engine = create_engine(database_url({str(tmp_path / "h.db")!r}))
        upgrade(engine)
        w = HistoryWriter(engine, interval_s=0.01, process=True)
        start = w.register_thing("d")
        w.start()
        w.submit(Record("d", start + 1, 0, "tick", 1, "1"))
        assert w.flush(30)
        print(w._process.pid, flush=True)
        time.sleep(60)
    """)
    hub = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    try:
        pid = int(hub.stdout.readline())
        os.kill(hub.pid, signal.SIGKILL)
        hub.wait(10)
        deadline = time.monotonic() + 10
        while _alive(pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not _alive(pid)
    finally:
        hub.kill()
        hub.wait()


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split()[2] != "Z"  # a zombie has exited (init reaps it)
    except FileNotFoundError:
        return False


def test_a_backlog_is_written_by_the_writers_thread_until_the_writer_keeps_up(tmp_path):
    """``_CATCH_UP``: the thread writes faster than the hand-over to the process allows."""
    engine = create_engine(database_url(tmp_path / "h.db"))
    upgrade(engine)
    w = HistoryWriter(engine, interval_s=0.01, batch_max=1_000, process=True)
    start = w.register_thing("d")
    for i in range(1, 30_001):  # queued before the writer starts: a backlog
        w.submit(Record("d", start + i, KIND_EVENT, "tick", 10**18 + i, str(i)))
    process = w._process
    by_process = []
    write = process.write
    process.write = lambda records, *a: (by_process.append(len(records)), write(records, *a))
    w.start()
    try:
        assert w.flush(60)
    finally:
        w.stop()
    assert w.written == 30_000 and w.batches == 30
    assert sum(by_process) == 20_000  # the last 20 batches: fewer than _CATCH_UP waiting behind each
    with engine.connect() as conn:
        assert [r[0] for r in conn.exec_driver_sql("SELECT seq FROM events ORDER BY id")] == \
            list(range(start + 1, start + 30_001))


def test_a_writer_that_keeps_up_writes_what_came_in_meanwhile_at_its_next_wake(tmp_path):
    """``_BEHIND``: records that arrive while a batch is written wait for the next wake (one batch per
    ``interval_s``, not one per write: each batch has fixed costs); a batch larger than a message
    (``_SLICE``) crosses in parts and is written whole."""
    engine = create_engine(database_url(tmp_path / "h.db"))
    upgrade(engine)
    w = HistoryWriter(engine, interval_s=60.0, process=True)  # woken by the flush below only
    start = w.register_thing("d")
    seq = iter(range(start + 1, start + 1_000))

    def submit(n: int) -> None:
        for _ in range(n):
            s = next(seq)
            w.submit(Record("d", s, KIND_EVENT, "tick", 10**18 + s, str(s)))

    submit(300)  # more than a message carries
    process = w._process
    sizes: list[int] = []
    write = process.write

    def writing(records, *a):
        if not sizes:
            submit(50)  # arriving while the first batch is written
        sizes.append(len(records))
        write(records, *a)

    process.write = writing
    w.start()
    try:
        deadline = time.monotonic() + 30
        while w.batches < 1 and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(0.3)
        assert (w.batches, w.written, w.queue_depth) == (1, 300, 50)  # the 50 wait for the next wake
        assert w.flush(30)
    finally:
        w.stop()
    assert sizes == [300, 50] and w.written == 350
    with engine.connect() as conn:
        assert [r[0] for r in conn.exec_driver_sql("SELECT seq FROM events ORDER BY id")] == \
            list(range(start + 1, start + 351))
