"""Batched history writer: a thread drains a queue into one transaction per batch.

The event loop only appends records to a deque (``submit``: no lock, no I/O).
The writer thread wakes every ``interval_s`` (or as soon as ``batch_max``
records are waiting), writes everything pending in one ``executemany`` and
one commit, moves each Thing's sequence reservation ahead in the same
transaction, and reports the committed watermarks back to the event plane.
A commit per event would cap SQLite at a few hundred events/s; a batch costs
about as much as one event.

If the database cannot keep up, the queue is bounded by ``queue_max``: beyond
it records are not recorded (counted in ``dropped``) rather than exhausting
memory; live subscribers still get them.
"""

from __future__ import annotations

import itertools
import logging
import threading
import time
from collections import deque
from collections.abc import Callable

import sqlalchemy as sa
from sqlalchemy.engine import Engine

from wott_hub.events.record import Record

from .models import EventRow, ThingRow
from .retention import Retention, apply_retention

__all__ = ["HistoryWriter", "RESERVE"]

log = logging.getLogger(__name__)

RESERVE = 1 << 20
"""How far ahead of its last committed record a Thing's sequence is reserved.

Records handed out but not yet committed stay below the reservation as long
as fewer than this many of one Thing wait in the queue (``queue_max`` keeps it so)."""

_COLUMNS = ("thing_key", "seq", "t_ns", "kind", "name", "data")


def positional_insert(engine: Engine, table: str, columns: tuple[str, ...], rows: int = 1) -> str | None:
    """An INSERT of ``rows`` rows in the driver's own positional paramstyle, taking the rows'
    values as one flat tuple; None if the paramstyle is not positional (use executemany).

    SQLAlchemy's Core insert would build a dict per row and process each value in
    Python; tuples go straight to the driver (3-4x faster on SQLite). Many rows per
    statement matter as much: the sqlite3 module releases the GIL around each
    statement step, and a thread that gets the GIL back only after the event loop's
    switch interval (5 ms) would take seconds to insert a batch row by row while
    holding the database's write lock, starving every other writer.
    """
    style = engine.dialect.paramstyle
    n = len(columns)
    if style == "qmark":
        groups = ["(" + ", ".join(["?"] * n) + ")"] * rows
    elif style in ("format", "pyformat"):
        groups = ["(" + ", ".join(["%s"] * n) + ")"] * rows
    elif style in ("numeric", "numeric_dollar"):
        mark = ":" if style == "numeric" else "$"
        groups = ["(" + ", ".join(f"{mark}{r * n + i + 1}" for i in range(n)) + ")" for r in range(rows)]
    else:  # named: not positional
        return None
    return f"INSERT INTO {table} ({', '.join(columns)}) VALUES {', '.join(groups)}"


def _named_insert(table: str, columns: tuple[str, ...]) -> str:
    return f"INSERT INTO {table} ({', '.join(columns)}) VALUES ({', '.join(':' + c for c in columns)})"


class HistoryWriter:
    def __init__(self, engine: Engine, *, batch_max: int = 20_000, interval_s: float = 0.05,
                 queue_max: int = RESERVE // 2, retention: Retention | None = None,
                 on_commit: Callable[[dict[str, int]], None] | None = None) -> None:
        self.engine = engine
        self.batch_max = batch_max
        self.interval_s = interval_s
        self.queue_max = min(queue_max, RESERVE // 2)
        self.retention = retention or Retention()
        self.on_commit = on_commit
        self.keys: dict[str, int] = {}
        self.committed: dict[str, int] = {}
        self._reserved: dict[str, int] = {}
        self.submitted = 0
        self.written = 0
        self.dropped = 0
        self.batches = 0
        self.last_batch_s = 0.0
        self.errors = 0
        self.last_error = ""
        self._queue: deque[Record] = deque()
        self._wake = threading.Event()
        self._stop = False
        self._thread: threading.Thread | None = None
        # rows per statement: SQLite before 3.32 allows 999 parameters, later 32766
        import sqlite3

        max_params = 999 if engine.dialect.name == "sqlite" and sqlite3.sqlite_version_info < (3, 32) \
            else 30_000
        self._chunk = max(1, min(1000, max_params // len(_COLUMNS)))
        self._insert_full = positional_insert(engine, EventRow.__tablename__, _COLUMNS, self._chunk)
        self._next_retention = 0.0

    # --- Things -------------------------------------------------------------------

    def register_thing(self, thing: str, *, title: str = "", family: str = "",
                       td: str | None = None, static_values: str | None = None) -> int:
        """Create or update the Thing's row; returns the last seq that may have been used.

        Called before the Thing publishes anything (the plane starts above it).
        """
        for attempt in range(8):
            try:
                return self._register(thing, title, family, td, static_values)
            except sa.exc.OperationalError as e:  # another process holds SQLite's write lock long
                if "locked" not in str(e) or attempt == 7:
                    raise
                time.sleep(0.05 * 2 ** attempt)
        raise AssertionError("unreachable")

    def _register(self, thing: str, title: str, family: str, td: str | None,
                  static_values: str | None) -> int:
        things = ThingRow.__table__
        events = EventRow.__table__
        now = time.time_ns()
        with self.engine.begin() as conn:
            # Write first: the transaction takes the write lock before it reads anything. (A
            # read first pins a WAL snapshot, and SQLite refuses at once, without waiting, to
            # turn a stale snapshot into a writer: "database is locked" under load.)
            conn.execute(things.update().where(things.c.id == thing).values(updated_ns=now))
            row = conn.execute(sa.select(things.c.key, things.c.seq_reserved)
                               .where(things.c.id == thing)).first()
            values = {"title": title or thing, "family": family, "updated_ns": now}
            if td is not None:
                values["td"] = td
            if static_values is not None:
                values["static_values"] = static_values
            if row is None:
                key = conn.execute(things.insert().values(id=thing, seq_reserved=0, **values)
                                   .returning(things.c.key)).scalar_one()
                reserved = 0
            else:
                key, reserved = row
                conn.execute(things.update().where(things.c.key == key).values(**values))
            last = conn.execute(sa.select(sa.func.max(events.c.seq))
                                .where(events.c.thing_key == key)).scalar() or 0
            start = max(reserved, last)
            # reserve before the first record is handed out: a crash before the first
            # commit must not let the next run reuse numbers clients have seen
            conn.execute(things.update().where(things.c.key == key)
                         .values(seq_reserved=start + RESERVE))
        self.keys[thing] = key
        self._reserved[thing] = start + RESERVE
        self.committed[thing] = start
        return start

    # --- the queue ----------------------------------------------------------------

    def submit(self, rec: Record) -> None:
        q = self._queue
        self.submitted += 1
        if len(q) >= self.queue_max:
            self.dropped += 1
            return
        q.append(rec)
        if len(q) >= self.batch_max:
            self._wake.set()

    @property
    def queue_depth(self) -> int:
        return len(self._queue)

    def start(self) -> None:
        if self._thread is not None:
            return
        self._stop = False
        self._thread = threading.Thread(target=self._run, name="history-writer", daemon=True)
        self._thread.start()

    def stop(self, timeout_s: float = 30.0) -> None:
        """Write everything queued, mark clean shutdown (no sequence gap on restart), stop."""
        if self._thread is None:
            return
        self._stop = True
        self._wake.set()
        self._thread.join(timeout_s)
        if self._thread.is_alive():
            log.error("history writer did not finish within %.0f s; %d records not written",
                      timeout_s, len(self._queue))
        self._thread = None
        self._release_reservations()

    def flush(self, timeout_s: float = 30.0) -> bool:
        """Block until everything submitted so far is committed (tests, benchmarks, export)."""
        deadline = time.monotonic() + timeout_s
        target = self.submitted
        self._wake.set()
        while self.written + self.dropped < target and time.monotonic() < deadline:
            if self._thread is None:
                self._write_pending()
            time.sleep(0.002)
        return self.written + self.dropped >= target

    # --- the thread ---------------------------------------------------------------

    def _run(self) -> None:
        while True:
            stopping = self._stop
            try:
                self._write_pending()
                if time.monotonic() >= self._next_retention:
                    self._next_retention = time.monotonic() + self.retention.check_every_s
                    if self.retention.active:
                        apply_retention(self.engine, self.retention)
            except Exception as e:  # keep recording: a failed batch is logged, the next one retried
                self.errors += 1
                self.last_error = str(e)
                log.exception("history batch failed")
                time.sleep(0.5)
            if stopping and not self._queue:
                return
            self._wake.wait(self.interval_s)
            self._wake.clear()

    def _write_pending(self) -> None:
        q = self._queue
        while q:
            n = min(len(q), self.batch_max)
            batch = [q.popleft() for _ in range(n)]
            try:
                self._write(batch)
            except Exception:
                q.extendleft(reversed(batch))  # retry them first next time
                raise

    def _write(self, batch: list[Record]) -> None:
        t0 = time.perf_counter()
        keys = self.keys
        rows = [(keys[r.thing], r.seq, r.t_ns, r.kind, r.name, r.data) for r in batch]
        tops: dict[str, int] = {}
        for r in batch:
            tops[r.thing] = r.seq  # records of one Thing arrive in seq order
        things = ThingRow.__table__
        with self.engine.begin() as conn:
            self._insert_rows(conn, rows)
            for thing, top in tops.items():
                # Invariant: every seq handed out is <= the reservation. At most queue_max
                # (<= RESERVE/2) records wait uncommitted, so moving the reservation when
                # less than RESERVE/2 is left keeps it; one UPDATE per ~500k records.
                if top > self._reserved[thing] - RESERVE // 2:
                    conn.execute(things.update().where(things.c.key == keys[thing])
                                 .values(seq_reserved=top + RESERVE))
                    self._reserved[thing] = top + RESERVE
        self.committed.update(tops)
        self.written += len(batch)
        self.batches += 1
        self.last_batch_s = time.perf_counter() - t0
        if self.on_commit is not None:
            self.on_commit(tops)

    def _insert_rows(self, conn, rows: list[tuple]) -> None:
        table = EventRow.__tablename__
        if self._insert_full is None:  # a driver with a named paramstyle: executemany
            conn.exec_driver_sql(_named_insert(table, _COLUMNS), [dict(zip(_COLUMNS, r, strict=True))
                                                                   for r in rows])
            return
        chunk = self._chunk
        for i in range(0, len(rows), chunk):
            part = rows[i:i + chunk]
            sql = self._insert_full if len(part) == chunk else positional_insert(
                self.engine, table, _COLUMNS, len(part))
            conn.exec_driver_sql(sql, tuple(itertools.chain.from_iterable(part)))

    def _release_reservations(self) -> None:
        """After a clean stop, the next run continues right after the last committed seq."""
        if self._queue:
            return  # not everything was written: keep the reservation (a gap, not a reuse)
        things = ThingRow.__table__
        try:
            with self.engine.begin() as conn:
                for thing, seq in self.committed.items():
                    conn.execute(things.update().where(things.c.key == self.keys[thing])
                                 .values(seq_reserved=seq))
                    self._reserved[thing] = seq
        except Exception:
            log.exception("could not release sequence reservations (the next run skips ahead)")
