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
- Store and forward (``spool``, ``spool.py``): when batches have failed for ``spill_after_s``,
  when the hub stops while they fail, or when told to ``hurry``, the records held in memory move
  to the spool on disk (then they count as durable: ``on_commit`` is told); the spool is forwarded
  before anything newer is written, oldest first, rows the database already has left out; a
  Thing registered while its records wait there continues above them. While it holds anything,
  health is "degraded" and a resume that needs history is refused (``DatabaseState.forwarding``).
- ``stop`` is bounded (``timeout_s``; ``hurry`` shortens it): a writer thread stuck in the
  database is left behind, and what it and the queue held goes to the spool. What could not be
  recorded is logged, never dropped without a word.
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
from .retention import Retention, RetentionClock
from .spool import Spool, SpoolRow
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
_BEHIND = 2_000
"""Records waiting after a batch from which the writer writes the next one at once rather than
at its next wake (``interval_s``). Below that it is keeping up, and a batch of what arrived while
the last one was written (~65 records at 32 devices x 120 Hz) would cost the batch process ~3x
as much a record as one wake's worth (~1,150 at 100 ms): encoding a batch and committing it have
fixed costs (measured: 96 against 31 µs of the process's CPU a frame; docs/history.md)."""
_HURRY_S = 1.0
"""After ``hurry``, how long ``stop`` still waits for the database before it spools and returns."""
_FORWARD_SLICE_S = 1.0
"""Forwarding works this long before the thread looks at its lease, its queue and ``stop`` again."""
_ENCODE_SLICE = 1_000
"""Records encoded per step of ``_Ahead``: about 4 ms, well under the ~20 ms of work that a
socket's buffer of COPY data gives PostgreSQL (and no dearer per record than a whole batch)."""


class HistoryWriter:
    degraded_s = 60.0  # health stays "degraded" this long after a record was refused

    def __init__(self, engine: Engine, *, batch_max: int = 20_000, interval_s: float = 0.05,
                 queue_max: int = RESERVE // 2, retention: Retention | None = None,
                 on_commit: Callable[[dict[str, int]], None] | None = None,
                 lease_stale_s: float = LEASE_STALE_S, integrity_check: bool = True,
                 hub_id: str = DEFAULT_HUB_ID, compact: bool = True, process: bool = False,
                 spool: Spool | None = None, spill_after_s: float = 2.0) -> None:
        """``engine``: the database, written through its storage engine (``engines.open_storage``).
        ``hub_id``: the identity of the hub this writer records for (its lease row, see
        ``lease.py``): hubs of different ids may share one database, each its own Things.
        ``compact``: skin packets stored packed (``codec.py``); False stores every payload as
        its UTF-8 text (what revision 0005 stored; the storage benchmark's "before").
        ``spool``: where records go when the database cannot take them (opened here: ``Conflict``
        if another process has it); ``spill_after_s``: how long batches may fail before they do."""
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
        self._retention_clock = RetentionClock(self.retention, engine)
        self.spool = spool
        self.spill_after_s = spill_after_s
        self.spooled = 0  # records moved to the spool (this run)
        self.forwarded = 0  # records written from the spool (any run's)
        self._failing_since: float | None = None
        self._hurry = False
        self._abandoned = False  # stop() gave up waiting: the thread must not touch queue or spool
        self._lock = threading.Lock()  # the spool, the queue's hand-overs, ``_inflight``
        self._inflight: list[list[Record]] = []  # batches taken from the queue, not yet done
        self._taken_at = 0.0  # time.monotonic() the last batch was taken
        self._started: dict[str, int] = {}  # the seq each Thing registered this run started after
        if spool is not None:
            spool.open()
            self._note_spool()

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
        if self.spool is not None:  # its records still waiting in the spool were handed out too
            start = max(start, self.spool.max_seq.get(thing, 0))
        self.committed[thing] = start
        self._started[thing] = start
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
        elif self.spool is not None and self.spool.records:
            state, reason = "degraded", (f"{self.spool.records} records wait in the spool to be written "
                                         "to the database")
        elif now - self._last_refused < self.degraded_s:
            state, reason = "degraded", (f"{self.failed_records} records could not be recorded; "
                                         f"last: {self.last_error}")
        elif now - db.last_read_error_at < self.degraded_s:
            state, reason = "degraded", f"history read failed: {db.last_read_error}"
        return {"state": state, "reason": reason, "written": self.written, "queued": self.queue_depth,
                "dropped": self.dropped, "failedRecords": self.failed_records, "errors": self.errors,
                "lastError": self.last_error, "readErrors": db.read_errors,
                "integrity": db.integrity or "unchecked", "lease": self._lease.held,
                **({"spool": self.spool_health()} if self.spool is not None else {})}

    def spool_health(self) -> dict[str, Any]:
        """What waits in the spool: records, bytes, the age of the oldest, what went where."""
        sp = self.spool
        assert sp is not None
        oldest = sp.oldest_t_ns  # the age of what waits: since the oldest record was made
        return {"path": str(sp.folder), "records": sp.records, "bytes": sp.bytes, "maxBytes": sp.max_bytes,
                "oldestAgeS": None if oldest is None else round(max(0.0, (time.time_ns() - oldest) / 1e9), 3),
                "spooled": self.spooled, "forwarded": self.forwarded, "dropped": sp.dropped}

    def hurry(self) -> None:
        """Stop waiting for the database (a second Ctrl-C): if batches are failing, or one has been in
        the database's hands for ``_HURRY_S`` already, what is held goes to the spool now (in a thread
        of its own: the disk may be slow too), whatever the rest of the stop is doing; from now on a
        failing batch goes there at once, and ``stop`` waits at most ``_HURRY_S`` more."""
        self._hurry = True
        self._wake.set()
        stuck = self._inflight and time.monotonic() - self._taken_at > _HURRY_S
        if self.spool is not None and (self._failing or stuck):
            threading.Thread(target=self._spill_held, name="history-hurry", daemon=True).start()

    def _spill_held(self) -> None:
        """The batches in the database's hands and the queue onto the spool (a batch committed after
        all is left out when the spool is forwarded); the thread does not put them back."""
        with self._lock:
            if self._abandoned:
                return
            taken = self._inflight
            self._inflight = []
            held = [r for b in taken for r in b] + self._drain()
            if held and not self._spill_records(held):
                self._inflight = taken  # the disk refused: still held, reported at stop
                self._queue.extendleft(reversed(held[sum(len(b) for b in taken):]))

    def stop(self, timeout_s: float = 10.0) -> None:
        """Write everything queued (and what the spool holds), mark clean shutdown (no sequence gap
        on restart), stop; within ``timeout_s`` whatever the database does: past it (or ``_HURRY_S``
        after ``hurry``) the thread is left behind and what it holds goes to the spool."""
        thread = self._thread
        if thread is None:
            if self.spool is not None:  # never started: its spool is free for the next writer
                self.spool.close()
            return
        self._stop = True
        self._wake.set()
        t0 = time.monotonic()
        deadline = t0 + timeout_s
        hurried = False
        while thread.is_alive() and time.monotonic() < deadline:
            thread.join(0.05)
            if self._hurry and not hurried:
                hurried, deadline = True, min(deadline, time.monotonic() + _HURRY_S)
        self._thread = None
        if thread.is_alive():
            self._abandon(time.monotonic() - t0)
        if self._process is not None:
            self._process.close()
        if not (self._abandoned or self._failing):  # a database that fails or hangs is not asked again
            self._release_reservations()
            try:
                self._lease.release()
            except Exception as e:  # the next hub takes it over once stale (or at once: this pid is gone)
                log.warning("could not release the history writer lease: %s", e)
        self._report()
        if self.spool is not None:
            self.spool.close()

    def _abandon(self, waited_s: float) -> None:
        """The thread is stuck in the database: the batches it holds and the queue go to the spool
        (a batch it commits after all is left out when the spool is forwarded)."""
        log.error("the history writer did not finish in %.1f s (the database does not answer); "
                  "what it holds goes to the spool", waited_s)
        if not self._lock.acquire(timeout=2.0):
            self._abandoned = True
            return
        try:
            self._abandoned = True
            held = [r for b in self._inflight for r in b] + self._drain()
            self._inflight.clear()
            if held and not self._spill_records(held):
                self._queue.extend(held)  # reported as not recorded
        finally:
            self._lock.release()

    def _report(self) -> None:
        """At stop: say what did not reach the database, and where it is."""
        waiting = self.spool.records if self.spool is not None else 0
        if waiting:
            assert self.spool is not None
            log.warning("history: %d records could not be written to the database and wait in the spool "
                        "%s; they are written when the database answers (at the next start)",
                        waiting, self.spool.folder)
        lost = len(self._queue) + sum(len(b) for b in self._inflight)
        if lost:
            log.error("history: %d records were not recorded (the database did not answer%s)", lost,
                      "" if self.spool is not None else " and there is no spool")
        if self.dropped:
            log.error("history: %d records were not recorded in all (queue or spool full, or the writer "
                      "lease lost)", self.dropped + lost)

    def outcome(self) -> dict[str, int]:
        """What became of the records (for a stop report): written, waiting in the spool, not recorded."""
        lost = len(self._queue) + sum(len(b) for b in self._inflight)
        return {"written": self.written, "spooled": self.spool.records if self.spool is not None else 0,
                "lost": self.dropped + lost + self.failed_records}

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
        while not self._abandoned:
            stopping = self._stop
            try:
                self._refresh_lease()
                if self._spool_waiting():  # older than anything queued: first
                    self._forward()
                if not self._spool_waiting():
                    self._write_pending()
                elif len(self._queue) >= self.batch_max:  # forwarding takes a while: keep memory bounded
                    self._spill()
                self._failing, self._failing_since = False, None
                backoff = 0.1
                if self._retention_clock.due():  # by time, and by the bytes written (retention.py)
                    self.storage.apply_retention(self.retention)  # the audit trail's bound even when off
                    self._retention_clock.done()
            except Exception as e:  # keep recording: a failed batch is logged, the rest retried
                if self._abandoned:
                    return
                now = time.monotonic()
                self.errors += 1
                self.last_error = driver_message(e)
                self._failing = True
                self._failing_since = self._failing_since or now
                if "database disk image is malformed" in self.last_error:
                    self._db.read_failed(self.last_error)
                spill = self.spool is not None and (stopping or self._hurry
                                                    or now - self._failing_since >= self.spill_after_s)
                log.error("history batch failed (%s): %s", "moving what is queued to the spool" if spill
                          else f"retrying in {backoff:.1f} s", self.last_error)
                if spill:
                    self._spill()
                if stopping:
                    failures_at_stop += 1
                    if not self._queue or failures_at_stop >= 3:  # stop() must end: the rest is reported
                        return
                self._wake.wait(backoff)  # a stop or a hurry cuts it short
                self._wake.clear()
                backoff = min(backoff * 2, 5.0)
                continue
            if stopping:
                if self._queue and self._spool_waiting():  # the spool is forwarded at the next start
                    self._spill()
                if not self._queue:
                    return
            self._wake.wait(self.interval_s)
            self._wake.clear()

    # --- store and forward --------------------------------------------------------------------

    def _spool_waiting(self) -> bool:
        return self.spool is not None and self.spool.records > 0

    def _note_spool(self) -> None:
        """Tell readers whether history lacks records that wait in the spool (a resume then waits)."""
        sp = self.spool
        self._db.forwarding = (f"{sp.records} records wait in the spool {str(sp.folder)!r} to be written "
                               "to the database" if sp is not None and sp.records else "")

    def _spill(self) -> None:
        """Move everything queued to the spool's tail (then it is durable: ``on_commit``)."""
        with self._lock:
            if self._abandoned or not self._queue:
                return
            records = self._drain()
            if not self._spill_records(records):
                self._queue.extendleft(reversed(records))  # kept in memory (bounded by queue_max)

    def _drain(self) -> list[Record]:
        """Everything queued, taken off (a record submitted meanwhile stays queued: never lost)."""
        q = self._queue
        return [q.popleft() for _ in range(len(q))]

    def _spill_records(self, records: list[Record]) -> bool:
        """``records`` onto the spool (the lock held); False if the disk refused them."""
        sp = self.spool
        if sp is None:
            return False
        try:
            payloads = self.storage.encode(records)
            rows: list[SpoolRow] = [(r.thing, r.seq, r.kind, r.name, r.t_ns, d)
                                    for r, d in zip(records, payloads, strict=True)]
            dropped = sp.append(rows)
        except Exception as e:
            log.error("history: cannot spool %d records: %s", len(records), e)
            return False
        self.spooled += len(records)
        self._note_spool()
        if dropped:
            self.dropped += dropped
            log.error("history: the spool %s is full (%d bytes): its %d oldest records were dropped",
                      sp.folder, sp.max_bytes, dropped)
        tops: dict[str, int] = {}
        for r in records:
            tops[r.thing] = r.seq
        if self.on_commit is not None:  # on disk: durable, as a commit is
            self.on_commit(tops)
        return True

    def _forward(self) -> None:
        """Write the spool's oldest segments to the database (for ``_FORWARD_SLICE_S`` at most), rows
        the database already has left out; a segment goes once all of it is in."""
        sp = self.spool
        assert sp is not None
        until = time.monotonic() + _FORWARD_SLICE_S
        while time.monotonic() < until and not self._abandoned:
            with self._lock:
                head = sp.head()
            if head is None:
                break
            seg, rows = head
            for i in range(0, len(rows), self.batch_max):
                self._forward_rows(rows[i:i + self.batch_max])
                if self._abandoned:
                    return
            with self._lock:
                sp.consumed(seg)
                self._note_spool()
        self._note_spool()

    def _forward_rows(self, rows: list[SpoolRow]) -> None:
        storage = self.storage
        by_thing: dict[str, tuple[int, int]] = {}
        for thing, seq, *_ in rows:
            lo, hi = by_thing.get(thing, (seq, seq))
            by_thing[thing] = (min(lo, seq), max(hi, seq))
        have: dict[str, set[int]] = {}
        unknown: set[str] = set()
        for thing, (lo, hi) in by_thing.items():
            if storage.known(thing):
                have[thing] = storage.recorded(thing, lo, hi)
            else:
                unknown.add(thing)
        batch: list[Record] = []
        payloads: list[bytes] = []
        mine = 0
        lost: dict[str, int] = {}
        for thing, seq, kind, name, t_ns, data in rows:
            if thing in unknown:
                lost[thing] = lost.get(thing, 0) + 1
                continue
            if seq in have[thing]:
                mine += self._mine(thing, seq)
                continue  # written before a crash, or by a thread stop() left behind
            batch.append(Record(thing, seq, kind, name, t_ns, ""))
            payloads.append(data)
        for thing, n in lost.items():  # cannot be: a Thing is registered before its first record
            self.failed_records += n
            self._last_refused = time.monotonic()
            self.last_error = (f"{n} spooled records of {thing!r} not recorded: the Thing is not in "
                               "the database")
            log.error("history: %s", self.last_error)
        if batch:
            before = self.written
            self._write_isolating(batch, _Given(payloads), requeue=False)
            wrote = self.written - before
            self.forwarded += wrote
            self.written = before + min(wrote, sum(self._mine(r.thing, r.seq) for r in batch))
        self.written += mine

    def _mine(self, thing: str, seq: int) -> int:
        """1 if the record was handed out in this run (``written`` and ``flush`` count those only)."""
        start = self._started.get(thing)
        return int(start is not None and seq > start)

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
        while (batch or q) and not self._lease.lost and not self._abandoned:
            if not batch:
                batch, encoded = self._take(), None
                if not batch:
                    break
            process = self._process if encoded is None and len(q) < _CATCH_UP else None
            ahead = _Ahead(self.storage, self._take()) \
                if self.storage.overlaps and process is None and len(q) >= _AHEAD_MIN else None
            self._write_isolating(batch, encoded, ahead, process)
            batch, encoded = ([], None) if ahead is None else (ahead.batch, ahead)
            if not batch and len(q) < _BEHIND and not (self._stop or self._hurry):
                break  # keeping up: what came in meanwhile waits for the next wake, a batch of its own
        if batch:  # taken ahead when the lease was lost: back in the queue, given up with it
            self._requeue(batch, [batch])

    def _take(self) -> list[Record]:
        """The next batch off the queue, kept in ``_inflight`` until it is done."""
        q = self._queue
        with self._lock:
            if self._abandoned:
                return []
            batch = [q.popleft() for _ in range(min(len(q), self.batch_max))]
            if batch:
                self._inflight.append(batch)
                self._taken_at = time.monotonic()
            return batch

    def _done(self, *batches: list[Record]) -> None:
        with self._lock:
            for b in batches:
                if any(x is b for x in self._inflight):
                    self._inflight = [x for x in self._inflight if x is not b]

    def _requeue(self, records: list[Record], batches: list[list[Record]]) -> None:
        """``records`` (what is left of ``batches``) back at the head of the queue, retried first."""
        with self._lock:
            held = [x for x in self._inflight if any(x is b for b in batches)]
            self._inflight = [x for x in self._inflight if not any(x is b for b in batches)]
            if not self._abandoned and len(held) == len(batches):  # else spooled already (stop, hurry)
                self._queue.extendleft(reversed(records))

    def _write_isolating(self, batch: list[Record], encoded: _Ahead | _Given | None = None,
                         ahead: _Ahead | None = None, process: BatchProcess | None = None, *,
                         requeue: bool = True) -> None:
        """Write ``batch`` (``encoded``: its payloads, encoded ahead; ``process``: by it); records the
        database refuses for their data are isolated by halving (log2(n) extra transactions per
        refused record) and given up on, the others written. Any other error puts every record
        not yet written back at the head of the queue, followed by ``ahead``'s (the next batch,
        taken and being encoded while this one is written); ``requeue`` False (records forwarded from
        the spool, which keeps them until they are in): nothing is put back."""
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
            if requeue:
                left = part + [r for p, _ in reversed(todo) for r in p]
                if ahead is not None:
                    left += ahead.batch
                self._requeue(left, [batch] if ahead is None else [batch, ahead.batch])  # retried first
            raise
        if requeue:
            self._done(batch)

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
        reserve = {thing: top + RESERVE for thing, top in tops.items()  # (a Thing of a previous run,
                   if thing in self._reserved  # forwarded from the spool: its registration reserves)
                   and top > self._reserved[thing] - RESERVE // 2 - 2 * self.batch_max}
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
        if self._queue or self._inflight or self._spool_waiting() or not self._lease.held:
            return  # not everything was written, or not ours to change: keep the reservation
        try:
            self.storage.release({t: s for t, s in self.committed.items() if t in self._reserved})
        except Exception:
            log.exception("could not release sequence reservations (the next run skips ahead)")
        else:
            self._reserved.update(self.committed)


class _Given:
    """A batch's payloads encoded already (records forwarded from the spool): what ``_Ahead`` gives."""

    prepared: Prepared | None = None

    def __init__(self, payloads: list[bytes]) -> None:
        self._payloads = payloads

    def result(self) -> list[bytes]:
        return self._payloads


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
