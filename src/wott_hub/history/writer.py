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

Contract (what keeps the writer from ever wedging):
- A batch the database refuses for its *data* (a unique-key conflict, a value
  it cannot store) is split in halves until the refused rows are isolated:
  every other row is written, each refused one is counted in
  ``failed_records``, named in ``last_error`` and given up on (its seq is
  passed to ``on_commit`` like a written one, and listed in ``failed_seqs``).
- Any other failure (locked, disk full, connection lost) keeps the rows not
  yet written at the head of the queue and retries with backoff.
- ``health()`` is "degraded" while batches fail, for ``degraded_s`` after a
  row was refused, and while the database is known to be corrupted
  (``PRAGMA quick_check`` at start, or a read error); "failed" once another
  process took the writer lease (this writer then records nothing more).
- The writer takes its hub's lease in the database (``lease.py``, keyed by
  ``hub_id``) before its first Thing is registered, refreshes it, and releases
  it at a clean stop: a second process of the same hub id on the same database
  gets ``Conflict`` instead of interleaving sequences; hubs of other ids write
  their own Things beside it.
"""

from __future__ import annotations

import itertools
import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import sqlalchemy as sa
from sqlalchemy.engine import Engine

from wott_hub.errors import Conflict, InvalidInput
from wott_hub.events.record import Record

from .codec import encode_records
from .db import HistoryError, check_integrity, describe
from .lease import DEFAULT_HUB_ID, LEASE_STALE_S, Lease, live_holder
from .models import EventRow, ThingRow
from .retention import Retention, apply_retention
from .state import state_of

__all__ = ["HistoryWriter", "RESERVE"]

log = logging.getLogger(__name__)

RESERVE = 1 << 20
"""How far ahead of its last committed record a Thing's sequence is reserved.

Records handed out but not yet committed stay below the reservation as long
as fewer than this many of one Thing wait in the queue (``queue_max`` keeps it so)."""

_COLUMNS = ("thing_key", "seq", "t_ns", "kind", "name", "data")
_Row = tuple[int, int, int, int, str, bytes]  # the values of _COLUMNS

_COPY_TYPES = ["int4", "int8", "int8", "int2", "varchar", "bytea"]
"""PostgreSQL types of ``_COLUMNS`` (models.EventRow) for a binary COPY."""

_DATA_ERRORS = (sa.exc.IntegrityError, sa.exc.DataError)
"""Errors about the rows themselves: retrying the same rows can never succeed; isolate them."""


class _Refused(Exception):
    """A record that cannot be written at all (its Thing was never registered)."""


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
    degraded_s = 60.0  # health stays "degraded" this long after a record was refused

    def __init__(self, engine: Engine, *, batch_max: int = 20_000, interval_s: float = 0.05,
                 queue_max: int = RESERVE // 2, retention: Retention | None = None,
                 on_commit: Callable[[dict[str, int]], None] | None = None,
                 lease_stale_s: float = LEASE_STALE_S, integrity_check: bool = True,
                 hub_id: str = DEFAULT_HUB_ID, compact: bool = True) -> None:
        """``hub_id``: the identity of the hub this writer records for (its lease row, see
        ``lease.py``): hubs of different ids may share one database, each its own Things.
        ``compact``: skin packets stored packed (``codec.py``); False stores every payload as
        its UTF-8 text (what revision 0005 stored; the storage benchmark's "before")."""
        # a bad value must be refused here: in the writer's thread it would kill it silently
        if not (isinstance(interval_s, int | float) and math.isfinite(interval_s) and 0 < interval_s <= 60):
            raise InvalidInput(f"history batch interval must be in (0, 60] s, got {interval_s!r}")
        if not (isinstance(batch_max, int) and 1 <= batch_max <= 1_000_000):
            raise InvalidInput(f"history batch size must be an integer in [1, 1000000], got {batch_max!r}")
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
        self.failed_records = 0
        self.failed_seqs: dict[str, set[int]] = {}
        """Seqs given up on per Thing (the plane drops them in ``committed`` mode, then discards them)."""
        self._failing = False  # the last batch attempt failed and is being retried
        self._last_refused = -1e9  # time.monotonic() of the last refused record
        self._db = state_of(engine)
        self.lease = Lease(engine, hub_id=hub_id, stale_s=lease_stale_s)
        self._next_refresh = 0.0
        self._integrity_check = integrity_check
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
        self._copy = engine.dialect.name == "postgresql" and engine.dialect.driver == "psycopg"
        self.compact = compact
        self._next_retention = 0.0

    # --- Things -------------------------------------------------------------------

    def register_thing(self, thing: str, *, title: str = "", family: str = "",
                       td: str | None = None, static_values: str | None = None) -> int:
        """Create or update the Thing's row; returns the last seq that may have been used.

        Called before the Thing publishes anything (the plane starts above it). The first
        call takes the database's writer lease: ``Conflict`` if another hub holds it.
        """
        self.acquire_lease()
        for attempt in range(8):
            try:
                return self._register(thing, title, family, td, static_values)
            except sa.exc.OperationalError as e:  # another process holds SQLite's write lock long
                if "locked" not in str(e) or attempt == 7:
                    raise
                time.sleep(0.05 * 2 ** attempt)
        raise AssertionError("unreachable")

    def acquire_lease(self) -> None:
        """Become the one writer of this database (``Conflict`` naming the holder if another
        process is). Done by the first ``register_thing``; a hub that must own the database
        before it registers anything (its directory shares it) calls it right after opening."""
        if self.lease.held:
            return
        if self.lease.lost:
            raise HistoryError(self.lease.lost)
        self.lease.acquire()
        self._next_refresh = time.monotonic() + self.lease.stale_s / 6

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
            row = conn.execute(sa.select(things.c.key, things.c.seq_reserved, things.c.hub_id)
                               .where(things.c.id == thing)).first()
            mine = self.lease.hub_id
            if row is not None and row[2] not in (None, mine):
                other = live_holder(conn, row[2], self.lease.stale_s)
                if other is not None:
                    raise Conflict(f"the Thing {thing!r} is recorded in the history database "
                                   f"{describe(self.engine.url)!r} by hub {row[2]!r} ({other}): two "
                                   "hubs cannot record the same Thing id; give each hub its own identity")
            values = {"title": title or thing, "family": family, "updated_ns": now, "hub_id": mine}
            if td is not None:
                values["td"] = td
            if static_values is not None:
                values["static_values"] = static_values
            if row is None:
                key = conn.execute(things.insert().values(id=thing, seq_reserved=0, **values)
                                   .returning(things.c.key)).scalar_one()
                reserved = 0
            else:
                key, reserved = row[0], row[1]
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
        if len(q) >= self.queue_max or self.lease.lost:
            self.dropped += 1
            self.failed_seqs.setdefault(rec.thing, set()).add(rec.seq)
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
        if self._integrity_check and self._db.integrity is None:
            # a full scan (~1 s per GB): off the start-up path and off the writer's thread
            threading.Thread(target=self._check_integrity, name="history-integrity", daemon=True).start()

    def _check_integrity(self) -> None:
        try:
            check_integrity(self.engine)
        except HistoryError as e:
            self._db.integrity = str(e)
            log.error("%s", e)
        except Exception as e:  # the check itself could not run: report, do not guess
            log.warning("history integrity check did not run: %s", e)
        else:
            if self._db.integrity is None:
                self._db.integrity = "ok"

    # --- health -------------------------------------------------------------------

    def health(self) -> dict[str, Any]:
        """``state`` ("ok", "degraded", "failed"), ``reason`` and the counters, for the hub's
        health property (``"history": writer.health()``)."""
        db = self._db
        now = time.monotonic()
        state, reason = "ok", ""
        if self.lease.lost:
            state, reason = "failed", self.lease.lost
        elif db.corrupted:
            state, reason = "degraded", db.corrupted
        elif self._failing:
            state, reason = "degraded", f"history batches are failing: {self.last_error}"
        elif now - self._last_refused < self.degraded_s:
            state, reason = "degraded", (f"{self.failed_records} records could not be recorded; "
                                         f"last: {self.last_error}")
        elif now - db.last_read_error_at < self.degraded_s:
            state, reason = "degraded", f"history read failed: {db.last_read_error}"
        return {"state": state, "reason": reason, "written": self.written, "queued": self.queue_depth,
                "dropped": self.dropped, "failedRecords": self.failed_records, "errors": self.errors,
                "lastError": self.last_error, "readErrors": db.read_errors,
                "integrity": db.integrity or "unchecked", "lease": self.lease.held}

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
        try:
            self.lease.release()
        except Exception as e:  # the next hub takes it over once stale (or at once: this pid is gone)
            log.warning("could not release the history writer lease: %s", e)

    def flush(self, timeout_s: float = 30.0) -> bool:
        """Block until everything submitted so far is committed (tests, benchmarks, export)."""
        deadline = time.monotonic() + timeout_s
        target = self.submitted
        self._wake.set()
        while self.written + self.dropped + self.failed_records < target and time.monotonic() < deadline:
            if self._thread is None:
                self._write_pending()
            time.sleep(0.002)
        return self.written + self.dropped + self.failed_records >= target

    # --- the thread ---------------------------------------------------------------

    def _run(self) -> None:
        backoff = 0.1
        failures_at_stop = 0
        while True:
            stopping = self._stop
            try:
                self._refresh_lease()
                self._write_pending()
                self._failing = False
                backoff = 0.1
                if time.monotonic() >= self._next_retention:
                    self._next_retention = time.monotonic() + self.retention.check_every_s
                    if self.retention.active:
                        apply_retention(self.engine, self.retention)
            except Exception as e:  # keep recording: a failed batch is logged, the rest retried
                self.errors += 1
                self.last_error = _one_line(e)
                self._failing = True
                if "database disk image is malformed" in self.last_error:
                    self._db.read_failed(self.last_error)
                log.error("history batch failed (retrying in %.1f s): %s", backoff, self.last_error)
                time.sleep(backoff)
                backoff = min(backoff * 2, 5.0)
                if stopping:
                    failures_at_stop += 1
                    if failures_at_stop >= 3:  # stop() must end: what is left is reported there
                        return
            if stopping and not self._queue:
                return
            self._wake.wait(self.interval_s)
            self._wake.clear()

    def _refresh_lease(self) -> None:
        if not self.lease.held or time.monotonic() < self._next_refresh:
            return
        self._next_refresh = time.monotonic() + self.lease.stale_s / 6
        if not self.lease.refresh():
            log.error("%s", self.lease.lost)
            self._give_up_queue()

    def _give_up_queue(self) -> None:
        """Lease lost: nothing more is written; the queue is counted as dropped and released."""
        q = self._queue
        tops: dict[str, int] = {}
        while q:
            r = q.popleft()
            self.dropped += 1
            tops[r.thing] = r.seq
            self.failed_seqs.setdefault(r.thing, set()).add(r.seq)
        if tops and self.on_commit is not None:
            self.on_commit(tops)

    def _write_pending(self) -> None:
        q = self._queue
        while q and not self.lease.lost:
            n = min(len(q), self.batch_max)
            batch = [q.popleft() for _ in range(n)]
            self._write_isolating(batch)

    def _write_isolating(self, batch: list[Record]) -> None:
        """Write ``batch``; rows the database refuses for their data are isolated by halving
        (log2(n) extra transactions per refused row) and given up on, the others written.
        Any other error puts every row not yet written back at the head of the queue."""
        todo = [batch]  # a stack, left halves on top: rows are written in seq order
        part: list[Record] = []
        try:
            while todo:
                part = todo.pop()
                try:
                    self._write(part)
                except _DATA_ERRORS + (_Refused,) as e:
                    if len(part) == 1:
                        self._refuse(part[0], e)
                        continue
                    mid = len(part) // 2
                    todo.append(part[mid:])
                    todo.append(part[:mid])
        except Exception:
            left = part + [r for p in reversed(todo) for r in p]
            self._queue.extendleft(reversed(left))  # retried first next time
            raise

    def _refuse(self, rec: Record, e: Exception) -> None:
        self.failed_records += 1
        self._last_refused = time.monotonic()
        self.last_error = f"{rec.thing} seq {rec.seq} not recorded: {_one_line(e)}"
        log.error("history: %s", self.last_error)
        self.failed_seqs.setdefault(rec.thing, set()).add(rec.seq)
        self.committed[rec.thing] = max(self.committed.get(rec.thing, 0), rec.seq)
        if self.on_commit is not None:
            self.on_commit({rec.thing: rec.seq})

    def _write(self, batch: list[Record]) -> None:
        t0 = time.perf_counter()
        keys = self.keys
        try:
            data = encode_records(batch) if self.compact else [r.data.encode() for r in batch]
            rows = [(keys[r.thing], r.seq, r.t_ns, r.kind, r.name, d)
                    for r, d in zip(batch, data, strict=True)]
        except KeyError as e:
            raise _Refused(f"Thing {e.args[0]!r} was never registered with the history writer") from None
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

    def _insert_rows(self, conn: sa.Connection, rows: list[_Row]) -> None:
        table = EventRow.__tablename__
        if self._copy:
            _copy_rows(conn, table, rows)
            return
        if self._insert_full is None:  # a driver with a named paramstyle: executemany
            conn.exec_driver_sql(_named_insert(table, _COLUMNS), [dict(zip(_COLUMNS, r, strict=True))
                                                                   for r in rows])
            return
        chunk = self._chunk
        for i in range(0, len(rows), chunk):
            part = rows[i:i + chunk]
            sql = self._insert_full if len(part) == chunk else positional_insert(
                self.engine, table, _COLUMNS, len(part))
            assert sql is not None  # positional, as _insert_full is
            conn.exec_driver_sql(sql, tuple(itertools.chain.from_iterable(part)))

    def _release_reservations(self) -> None:
        """After a clean stop, the next run continues right after the last committed seq."""
        if self._queue or not self.lease.held:
            return  # not everything was written, or not ours to change: keep the reservation
        things = ThingRow.__table__
        try:
            with self.engine.begin() as conn:
                for thing, seq in self.committed.items():
                    conn.execute(things.update().where(things.c.key == self.keys[thing])
                                 .values(seq_reserved=seq))
                    self._reserved[thing] = seq
        except Exception:
            log.exception("could not release sequence reservations (the next run skips ahead)")


def _copy_rows(conn: sa.Connection, table: str, rows: list[_Row]) -> None:
    """PostgreSQL through psycopg 3: ``COPY ... FROM STDIN`` in the batch's transaction.

    A multi-row INSERT makes psycopg adapt every parameter in Python and PostgreSQL parse
    a statement of 6,000 placeholders: ~6,000 rows/s measured; COPY streams the rows (its
    encoder is psycopg's C extension) at many times that. A row the database refuses fails
    the COPY as a whole, raised as SQLAlchemy's error class for it (IntegrityError,
    DataError...), so ``_write_isolating`` halves the batch exactly as for an INSERT.
    """
    sql = f"COPY {table} ({', '.join(_COLUMNS)}) FROM STDIN (FORMAT BINARY)"  # ~15 % over text
    import psycopg  # loaded already: the engine's driver

    dbapi_conn = conn.connection.dbapi_connection
    assert isinstance(dbapi_conn, psycopg.Connection)
    try:
        with dbapi_conn.cursor() as cur, cur.copy(sql) as copy:
            copy.set_types(_COPY_TYPES)
            for row in rows:
                copy.write_row(row)
    except conn.dialect.loaded_dbapi.Error as e:
        raise sa.exc.DBAPIError.instance(sql, None, e, conn.dialect.loaded_dbapi.Error) from None


def _one_line(e: BaseException) -> str:
    """The driver's message without SQLAlchemy's statement dump and background link."""
    text = str(getattr(e, "orig", None) or e)
    return text.splitlines()[0] if text else type(e).__name__
