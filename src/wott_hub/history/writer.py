"""Batched history writer: a thread drains a queue into one transaction per batch.

The event loop only appends records to a deque (``submit``: no lock, no I/O).
The writer thread wakes every ``interval_s`` (or as soon as ``batch_max``
records are waiting), writes everything pending in one transaction per batch,
moves each Thing's sequence reservation ahead in the same transaction, and
reports the committed watermarks back to the event plane. A commit per event
would cap SQLite at a few hundred events/s; a batch costs about as much as one event.

This is the part above the storage: queue, thread, batches, isolation of refused
records, watermarks, reservations, lease keeping, health. What the database does
with a batch is its storage engine's (``storage.StorageWriter``, chosen by the
engine's dialect: ``engines.py``), as rosbag2's writer keeps its cache and its
thread above its storage plugins.

If the database cannot keep up, the queue is bounded by ``queue_max``: beyond
it records are not recorded (counted in ``dropped``) rather than exhausting
memory; live subscribers still get them.

Contract (what keeps the writer from ever wedging):
- A batch the database refuses for its *data* (``RecordRefused``: a unique-key
  conflict, a value it cannot store, a Thing never registered) is split in halves
  until the refused records are isolated: every other record is written, each
  refused one is counted in ``failed_records``, named in ``last_error`` and given
  up on (its seq is passed to ``on_commit`` like a written one, and listed in ``failed_seqs``).
- Any other failure (locked, disk full, connection lost) keeps the records not
  yet written at the head of the queue and retries with backoff.
- ``health()`` is "degraded" while batches fail, for ``degraded_s`` after a
  record was refused, and while the database is known to be corrupted
  (``PRAGMA quick_check`` at start, or a read error); "failed" once another
  process took the writer lease (this writer then records nothing more).
- With ``process=True`` (the hub's ``history_process``, on by default) each batch is encoded
  and written by a process of its own (``batch_process.py``), off the GIL of the process that
  submits, while the writer keeps up (``_CATCH_UP``); the rest stays here. A process that exits
  fails the batch in hand, which is retried.
- The writer takes its hub's lease in the database (``lease.py``, keyed by
  ``hub_id``) before its first Thing is registered, refreshes it, and releases
  it at a clean stop: a second process of the same hub id on the same database
  gets ``Conflict`` instead of interleaving sequences; hubs of other ids write
  their own Things beside it.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any

from sqlalchemy.engine import Engine

from wott_hub.errors import HistoryError, InvalidInput, RecordRefused
from wott_hub.events.record import Record

from .batch_process import BatchProcess
from .db_errors import driver_message
from .engines import open_storage
from .lease import DEFAULT_HUB_ID, LEASE_STALE_S
from .retention import Retention
from .storage import Prepared, Step, StorageWriter

__all__ = ["HistoryWriter", "RESERVE"]

log = logging.getLogger(__name__)

RESERVE = 1 << 20
"""How far ahead of its last committed record a Thing's sequence is reserved.

Records handed out but not yet committed stay below the reservation as long
as fewer than this many of one Thing wait in the queue (``queue_max`` keeps it so)."""

_AHEAD_MIN = 1_000
"""Records that must wait behind a batch for the writer to take the next batch and encode it
while PostgreSQL writes this one: below that the writer is keeping up."""
_CATCH_UP = 20_000
"""Records waiting behind a batch from which the writer's thread writes it itself though it has a
batch process: catching up matters more then than the event loop's share of the GIL. The
process writes 29,000-54,000 records/s (the hand-over costs ~8 µs a record: pickling the
records, the pipe, unpickling them), the thread 67,000-82,000 (docs/history.md); a hub keeping
up has ~770 waiting per 50 ms batch at 64 devices x 120 Hz."""
_ENCODE_SLICE = 1_000
"""Records encoded per step of ``_Ahead``: about 4 ms, well under the ~20 ms of work that a
socket's buffer of COPY data gives PostgreSQL (and no dearer per record than a whole batch)."""


class HistoryWriter:
    degraded_s = 60.0  # health stays "degraded" this long after a record was refused

    def __init__(self, engine: Engine, *, batch_max: int = 20_000, interval_s: float = 0.05,
                 queue_max: int = RESERVE // 2, retention: Retention | None = None,
                 on_commit: Callable[[dict[str, int]], None] | None = None,
                 lease_stale_s: float = LEASE_STALE_S, integrity_check: bool = True,
                 hub_id: str = DEFAULT_HUB_ID, compact: bool = True, process: bool = False) -> None:
        """``engine``: the database, written through its storage engine (``engines.open_storage``).
        ``hub_id``: the identity of the hub this writer records for (its lease row, see
        ``lease.py``): hubs of different ids may share one database, each its own Things.
        ``compact``: skin packets stored packed (``codec.py``); False stores every payload as
        its UTF-8 text (what revision 0005 stored; the storage benchmark's "before")."""
        # a bad value must be refused here: in the writer's thread it would kill it silently
        if not (isinstance(interval_s, int | float) and math.isfinite(interval_s) and 0 < interval_s <= 60):
            raise InvalidInput(f"history batch interval must be in (0, 60] s, got {interval_s!r}")
        if not (isinstance(batch_max, int) and 1 <= batch_max <= 1_000_000):
            raise InvalidInput(f"history batch size must be an integer in [1, 1000000], got {batch_max!r}")
        self.storage = open_storage(engine, compact=compact, hub_id=hub_id, lease_stale_s=lease_stale_s)
        self.batch_max = batch_max
        self.interval_s = interval_s
        self.queue_max = min(queue_max, RESERVE // 2)
        self.retention = retention or Retention()
        self.on_commit = on_commit
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
        self._db = self.storage.state
        self._lease = self.storage.lease
        self._next_refresh = 0.0
        self._integrity_check = integrity_check
        self._queue: deque[Record] = deque()
        self._wake = threading.Event()
        self._stop = False
        self._thread: threading.Thread | None = None
        self._process = BatchProcess(self.storage.url, compact) if process else None  # batch_process.py
        self._next_retention = 0.0

    # --- Things -------------------------------------------------------------------

    def register_thing(self, thing: str, *, title: str = "", family: str = "",
                       td: str | None = None, static_values: str | None = None) -> int:
        """Create or update the Thing's row; returns the last seq that may have been used.

        Called before the Thing publishes anything (the plane starts above it). The first
        call takes the database's writer lease: ``Conflict`` if another hub holds it.
        """
        self.acquire_lease()
        start = self.storage.register(thing, title=title, family=family, td=td, static_values=static_values,
                                      ahead=RESERVE)
        self._reserved[thing] = start + RESERVE
        self.committed[thing] = start
        return start

    def acquire_lease(self) -> None:
        """Become the one writer of this database (``Conflict`` naming the holder if another
        process is). Done by the first ``register_thing``; a hub that must own the database
        before it registers anything (its directory shares it) calls it right after opening."""
        lease = self._lease
        if lease.held:
            return
        if lease.lost:
            raise HistoryError(lease.lost)
        lease.acquire()
        self._next_refresh = time.monotonic() + lease.stale_s / 6

    # --- the queue ----------------------------------------------------------------

    def submit(self, rec: Record) -> None:
        q = self._queue
        self.submitted += 1
        if len(q) >= self.queue_max or self._lease.lost:
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
            self.storage.check_integrity()
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
        if self._lease.lost:
            state, reason = "failed", self._lease.lost
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
                "integrity": db.integrity or "unchecked", "lease": self._lease.held}

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
        if self._process is not None:
            self._process.close()
        self._release_reservations()
        try:
            self._lease.release()
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
        if self._process is not None:
            try:
                self._process.start()
            except HistoryError as e:  # the first batch starts it again, or reports why not
                log.warning("%s", e)
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
                        self.storage.apply_retention(self.retention)
            except Exception as e:  # keep recording: a failed batch is logged, the rest retried
                self.errors += 1
                self.last_error = driver_message(e)
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
        lease = self._lease
        if not lease.held or time.monotonic() < self._next_refresh:
            return
        self._next_refresh = time.monotonic() + lease.stale_s / 6
        if not lease.refresh():
            log.error("%s", lease.lost)
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
        """Write the queue batch by batch, each by the batch process if there is one and fewer than
        ``_CATCH_UP`` records wait behind it, else here. Here, with a storage that ``overlaps``
        (PostgreSQL), while more records wait, the next batch is taken too and its payloads
        encoded (``codec.py``, Python: about as costly as the server's work) a slice at a time,
        then its rows prepared, while the server works through this batch's data: the two
        costs overlap instead of adding up. In this thread, between its socket writes, not in
        another one: a second thread would hold the GIL while the socket waits for more data,
        and each hand-over takes up to the interpreter's 5 ms switch interval (measured: no
        faster than without overlap)."""
        q = self._queue
        batch: list[Record] = []
        encoded: _Ahead | None = None
        while (batch or q) and not self._lease.lost:
            if not batch:
                batch, encoded = self._take(), None
            process = self._process if encoded is None and len(q) < _CATCH_UP else None
            ahead = _Ahead(self.storage, self._take()) \
                if self.storage.overlaps and process is None and len(q) >= _AHEAD_MIN else None
            self._write_isolating(batch, encoded, ahead, process)
            batch, encoded = ([], None) if ahead is None else (ahead.batch, ahead)
        if batch:  # taken ahead when the lease was lost: back in the queue, given up with it
            q.extendleft(reversed(batch))

    def _take(self) -> list[Record]:
        q = self._queue
        return [q.popleft() for _ in range(min(len(q), self.batch_max))]

    def _write_isolating(self, batch: list[Record], encoded: _Ahead | None = None,
                         ahead: _Ahead | None = None, process: BatchProcess | None = None) -> None:
        """Write ``batch`` (``encoded``: its payloads, encoded ahead; ``process``: by it); records the
        database refuses for their data are isolated by halving (log2(n) extra transactions per
        refused record) and given up on, the others written. Any other error puts every record
        not yet written back at the head of the queue, followed by ``ahead``'s (the next batch,
        taken and being encoded while this one is written)."""
        todo: list[tuple[list[Record], list[bytes] | None]] = []  # a stack, left halves on top:
        part: list[Record] = batch  # records are written in seq order
        prepared = None if encoded is None else encoded.prepared  # for the whole batch only
        try:
            todo.append((batch, None if encoded is None else encoded.result()))
            while todo:
                part, payloads = todo.pop()
                try:
                    self._write(part, payloads, None if ahead is None else ahead.step,
                                prepared if part is batch else None, process)
                except RecordRefused as e:
                    if len(part) == 1:
                        self._refuse(part[0], e)
                        continue
                    mid = len(part) // 2
                    todo.append((part[mid:], None if payloads is None else payloads[mid:]))
                    todo.append((part[:mid], None if payloads is None else payloads[:mid]))
        except Exception:
            left = part + [r for p, _ in reversed(todo) for r in p]
            if ahead is not None:
                left += ahead.batch
            self._queue.extendleft(reversed(left))  # retried first next time
            raise

    def _refuse(self, rec: Record, e: Exception) -> None:
        self.failed_records += 1
        self._last_refused = time.monotonic()
        self.last_error = f"{rec.thing} seq {rec.seq} not recorded: {driver_message(e)}"
        log.error("history: %s", self.last_error)
        self.failed_seqs.setdefault(rec.thing, set()).add(rec.seq)
        self.committed[rec.thing] = max(self.committed.get(rec.thing, 0), rec.seq)
        if self.on_commit is not None:
            self.on_commit({rec.thing: rec.seq})

    def _write(self, batch: list[Record], payloads: list[bytes] | None = None, meanwhile: Step | None = None,
               prepared: Prepared | None = None, process: BatchProcess | None = None) -> None:
        """One transaction, here or in ``process``; ``meanwhile``: work to do in steps while the
        database takes the data (it returns False when done); ``prepared``: the batch, ready."""
        t0 = time.perf_counter()
        storage = self.storage
        tops: dict[str, int] = {}
        for r in batch:
            tops[r.thing] = r.seq  # records of one Thing arrive in seq order
        if process is not None:  # the records as they are: the process encodes them
            try:
                keys = {thing: storage.keys[thing] for thing in tops}
            except KeyError as e:
                raise RecordRefused(f"Thing {e.args[0]!r} was never registered with the history writer") \
                    from None
        elif prepared is None:
            prepared = storage.prepare(batch, payloads)
        # Invariant: every seq handed out is <= the reservation. At most queue_max
        # (<= RESERVE/2) records wait in the queue and two batches are taken from it
        # (this one and the next, encoded ahead), so moving the reservation when less
        # than RESERVE/2 + 2 batches is left keeps it (batch_max up to RESERVE/4, as
        # the default; larger ones move it every batch); one UPDATE per ~450k records.
        reserve = {thing: top + RESERVE for thing, top in tops.items()
                   if top > self._reserved[thing] - RESERVE // 2 - 2 * self.batch_max}
        if process is not None:
            process.write(batch, keys, reserve)
        else:
            assert prepared is not None
            storage.write(prepared, reserve, meanwhile)
        self._reserved.update(reserve)
        self.committed.update(tops)
        self.written += len(batch)
        self.batches += 1
        self.last_batch_s = time.perf_counter() - t0
        if self.on_commit is not None:
            self.on_commit(tops)

    def _release_reservations(self) -> None:
        """After a clean stop, the next run continues right after the last committed seq."""
        if self._queue or not self._lease.held:
            return  # not everything was written, or not ours to change: keep the reservation
        try:
            self.storage.release(self.committed)
        except Exception:
            log.exception("could not release sequence reservations (the next run skips ahead)")
        else:
            self._reserved.update(self.committed)


class _Ahead:
    """The next batch, its payloads encoded a slice at a time (``step``) while the current batch
    is written, then prepared (``prepared``); ``result`` encodes what is left. An error encoding
    is kept for ``result``: it belongs to this batch, not to the one being written; one preparing
    leaves ``prepared`` None (``_write`` prepares it again and raises it, for that batch)."""

    def __init__(self, storage: StorageWriter, batch: list[Record]) -> None:
        self.batch = batch
        self.prepared: Prepared | None = None
        self._encode: Callable[[Sequence[Record]], list[bytes]] = storage.encode
        self._prepare: Callable[[Sequence[Record], list[bytes]], Prepared] | None = storage.prepare
        self._parts: list[list[bytes]] = []
        self._done = 0
        self._error: Exception | None = None

    def step(self) -> bool:
        """Encode one more slice, or prepare the batch once all are; False once nothing is left."""
        if self._error is not None:
            return False
        if self._done >= len(self.batch):
            prepare, self._prepare = self._prepare, None
            if prepare is None:
                return False
            try:
                self.prepared = prepare(self.batch, self.result())
            except Exception:
                pass  # _write prepares again, and raises it for this batch
            return False
        part = self.batch[self._done:self._done + _ENCODE_SLICE]
        try:
            self._parts.append(self._encode(part))
        except Exception as e:
            self._error = e
            return False
        self._done += len(part)
        return True

    def result(self) -> list[bytes]:
        while self._error is None and self._done < len(self.batch):
            self.step()
        if self._error is not None:
            raise self._error
        return [d for part in self._parts for d in part]
