"""Batched history writer: a thread drains a queue into one transaction per batch.

The event loop only appends records to a deque (``submit``: no lock, no I/O).
The writer thread wakes every ``interval_s`` (or as soon as ``batch_max``
records are waiting), writes everything pending in one transaction per batch,
moves each Thing's sequence reservation ahead in the same transaction, and
reports the committed watermarks back to the event plane. A commit per event
would cap SQLite at a few hundred events/s; a batch costs about as much as one event.

This is the part above the storage, a few pieces of one job each that ``HistoryWriter``
composes (as rosbag2 keeps its cache, its writer thread and its storage plugins apart):
- ``record_queue.RecordQueue``: the queue, its bounds, the batches in flight;
- ``batch_writer.BatchWriter``: what a batch is and how it is written (``ahead.py``: the next
  batch encoded while this one is written; the bisection isolating refused records;
  reservations and watermarks);
- ``forward.StoreAndForward``: spilling to the spool and forwarding from it;
- ``writer_loop.WriterLoop``: the thread (its rounds, backoff, retention);
- ``tally.Tally``: the counters they share, read by ``health``; the lease is kept by
  ``lease.Lease.keep``, the integrity check's outcome by ``state.DatabaseState.check``.
What the database does with a batch is its storage engine's (``storage.StorageWriter``, chosen by
the engine's dialect: ``engines.py``).

If the database cannot keep up, the queue is bounded by ``queue_max`` records and
``queue_max_bytes`` bytes: beyond either, records are not recorded (counted in ``dropped``)
rather than exhausting memory; live subscribers still get them.

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
  submits, while the writer keeps up (``batch_writer.CATCH_UP``); the rest stays here. A process that exits
  fails the batch in hand, which is retried.
- The writer takes its hub's lease in the database (``lease.py``, keyed by
  ``hub_id``) before its first Thing is registered, refreshes it, and releases
  it at a clean stop: a second process of the same hub id on the same database
  gets ``Conflict`` instead of interleaving sequences; hubs of other ids write
  their own Things beside it.
- Store and forward (``spool``, ``spool.py``): when batches have failed for ``spill_after_s``,
  when the hub stops while they fail, when told to ``hurry``, or when the queue holds half its
  byte budget while they fail, the records held in memory move
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
from collections.abc import Callable
from typing import Any, Generic, TypeVar, cast

from sqlalchemy.engine import Engine

from wott_hub.errors import HistoryError, InvalidInput
from wott_hub.events.record import Record

from .batch_process import BatchProcess
from .batch_writer import RESERVE, BatchWriter
from .engines import open_storage
from .forward import StoreAndForward
from .lease import DEFAULT_HUB_ID, LEASE_STALE_S
from .record_queue import QUEUE_BYTES, RecordQueue
from .retention import Retention, RetentionClock
from .spool import Spool
from .tally import Tally
from .writer_loop import HURRY_S, WriterLoop

__all__ = ["HistoryWriter", "RESERVE"]

log = logging.getLogger(__name__)

T = TypeVar("T")


class _Of(Generic[T]):
    """An attribute of one of the writer's pieces, read (and set) as the writer's own: the names the
    hub, its health and its tests have always used (``w.written``, ``w._next_refresh``)."""

    def __init__(self, part: str, name: str = "") -> None:
        self.part, self.name = part, name

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = self.name or name

    def __get__(self, obj: Any, owner: Any = None) -> T:
        return cast(T, getattr(getattr(obj, self.part), self.name))

    def __set__(self, obj: Any, value: T) -> None:
        setattr(getattr(obj, self.part), self.name, value)


class HistoryWriter:
    degraded_s = 60.0  # health stays "degraded" this long after a record was refused

    on_commit = _Of[Callable[[dict[str, int]], None] | None]("tally")
    committed = _Of[dict[str, int]]("tally")
    failed_seqs = _Of[dict[str, set[int]]]("tally")
    submitted = _Of[int]("tally")
    written = _Of[int]("tally")
    dropped = _Of[int]("tally")
    batches = _Of[int]("tally")
    last_batch_s = _Of[float]("tally")
    errors = _Of[int]("tally")
    last_error = _Of[str]("tally")
    failed_records = _Of[int]("tally")
    spooled = _Of[int]("tally")
    forwarded = _Of[int]("tally")
    retention = _Of[Retention]("loop")
    spill_after_s = _Of[float]("loop")
    _stop = _Of[bool]("loop", "stopping")
    _retention_clock = _Of[RetentionClock]("loop", "retention_clock")
    _next_refresh = _Of[float]("_lease", "next_refresh")
    _wake = _Of[threading.Event]("queue", "wake")
    _process = _Of[BatchProcess | None]("writes", "process")

    def __init__(self, engine: Engine, *, batch_max: int = 20_000, interval_s: float = 0.05,
                 queue_max: int = RESERVE // 2, queue_max_bytes: int = QUEUE_BYTES,
                 retention: Retention | None = None,
                 on_commit: Callable[[dict[str, int]], None] | None = None,
                 lease_stale_s: float = LEASE_STALE_S, integrity_check: bool = True,
                 hub_id: str = DEFAULT_HUB_ID, compact: bool = True, process: bool = False,
                 spool: Spool | None = None, spill_after_s: float = 2.0) -> None:
        """``engine``: the database, written through its storage engine (``engines.open_storage``).
        ``hub_id``: the identity of the hub this writer records for (its lease row, see
        ``lease.py``): hubs of different ids may share one database, each its own Things.
        ``compact``: skin packets stored packed (``codec.py``); False stores every payload as
        its UTF-8 text (what revision 0005 stored; the storage benchmark's "before").
        ``queue_max``/``queue_max_bytes``: the queue's bounds in records and in (estimated) bytes.
        ``spool``: where records go when the database cannot take them (opened here: ``Conflict``
        if another process has it); ``spill_after_s``: how long batches may fail before they do."""
        # a bad value must be refused here: in the writer's thread it would kill it silently
        if not (isinstance(interval_s, int | float) and math.isfinite(interval_s) and 0 < interval_s <= 60):
            raise InvalidInput(f"history batch interval must be in (0, 60] s, got {interval_s!r}")
        if not (isinstance(batch_max, int) and 1 <= batch_max <= 1_000_000):
            raise InvalidInput(f"history batch size must be an integer in [1, 1000000], got {batch_max!r}")
        if not (isinstance(queue_max_bytes, int) and queue_max_bytes >= 1):
            raise InvalidInput(f"history queue bytes must be a positive integer, got {queue_max_bytes!r}")
        self.storage = storage = open_storage(engine, compact=compact, hub_id=hub_id,
                                              lease_stale_s=lease_stale_s)
        self.batch_max = batch_max
        self.interval_s = interval_s
        self.queue_max = min(queue_max, RESERVE // 2)
        self.spool = spool
        self._db = storage.state
        self._lease = storage.lease
        self._integrity_check = integrity_check
        self.tally = Tally(on_commit)
        self.queue = RecordQueue(max_records=self.queue_max, max_bytes=queue_max_bytes, batch_max=batch_max)
        self.writes = BatchWriter(storage, self.queue, self.tally, self._lease, batch_max=batch_max,
                                  process=BatchProcess(storage.url, compact) if process else None)
        self.forwarder = StoreAndForward(spool, storage, self.queue, self.tally, self.writes, self._db)
        policy = retention or Retention()
        self.loop = WriterLoop(storage, self.queue, self.tally, self.writes, self.forwarder, self._db,
                               interval_s=interval_s, spill_after_s=spill_after_s,
                               retention=policy, retention_clock=RetentionClock(policy, engine))
        self.forwarder.open()

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
        self.writes.reserved[thing] = start + RESERVE
        if self.spool is not None:  # its records still waiting in the spool were handed out too
            start = max(start, self.spool.max_seq.get(thing, 0))
        self.tally.committed[thing] = start
        self.tally.started[thing] = start
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
        lease.acquire()  # it is refreshed by the writer's thread (``Lease.keep``)

    # --- the queue ----------------------------------------------------------------

    def submit(self, rec: Record) -> None:
        t = self.tally
        t.submitted += 1
        if self._lease.lost or not self.queue.offer(rec):
            t.dropped += 1
            t.give_up(rec.thing, rec.seq)

    @property
    def queue_depth(self) -> int:
        return len(self.queue)

    def start(self) -> None:
        if self.loop.thread is not None:
            return
        self.loop.start()
        if self._integrity_check and self._db.integrity is None:
            # a full scan (~1 s per GB): off the start-up path and off the writer's thread
            threading.Thread(target=self._db.check, args=(self.storage.check_integrity,),
                             name="history-integrity", daemon=True).start()

    # --- health -------------------------------------------------------------------

    def health(self) -> dict[str, Any]:
        """``state`` ("ok", "degraded", "failed"), ``reason`` and the counters, for the hub's
        health property (``"history": writer.health()``)."""
        db, t = self._db, self.tally
        now = time.monotonic()
        state, reason = "ok", ""
        if self._lease.lost:
            state, reason = "failed", self._lease.lost
        elif db.corrupted:
            state, reason = "degraded", db.corrupted
        elif t.failing:
            state, reason = "degraded", f"history batches are failing: {t.last_error}"
        elif self.forwarder.waiting:
            state, reason = "degraded", (f"{self.forwarder.waiting} records wait in the spool to be written "
                                         "to the database")
        elif now - t.last_refused < self.degraded_s:
            state, reason = "degraded", (f"{t.failed_records} records could not be recorded; "
                                         f"last: {t.last_error}")
        elif now - db.last_read_error_at < self.degraded_s:
            state, reason = "degraded", f"history read failed: {db.last_read_error}"
        return {"state": state, "reason": reason, "written": t.written, "queued": self.queue_depth,
                "queuedBytes": self.queue.bytes, "dropped": t.dropped, "failedRecords": t.failed_records,
                "errors": t.errors, "lastError": t.last_error, "readErrors": db.read_errors,
                "integrity": db.integrity or "unchecked", "lease": self._lease.held,
                **({"spool": self.spool_health()} if self.spool is not None else {})}

    def spool_health(self) -> dict[str, Any]:
        """What waits in the spool: records, bytes, the age of the oldest, what went where."""
        return self.forwarder.health()

    def hurry(self) -> None:
        """Stop waiting for the database (a second Ctrl-C): if batches are failing, or one has been in
        the database's hands for ``HURRY_S`` already, what is held goes to the spool now (in a thread
        of its own: the disk may be slow too), whatever the rest of the stop is doing; from now on a
        failing batch goes there at once, and ``stop`` waits at most ``HURRY_S`` more."""
        self.loop.hurried = True
        self.queue.wake.set()
        stuck = self.queue.inflight and time.monotonic() - self.queue.taken_at > HURRY_S
        if self.spool is not None and (self.tally.failing or stuck):
            threading.Thread(target=self.forwarder.spill_held, name="history-hurry", daemon=True).start()

    def stop(self, timeout_s: float = 10.0) -> None:
        """Write everything queued (and what the spool holds), mark clean shutdown (no sequence gap
        on restart), stop; within ``timeout_s`` whatever the database does: past it (or ``HURRY_S``
        after ``hurry``) the thread is left behind and what it holds goes to the spool."""
        if self.loop.thread is None:
            self.forwarder.close()  # never started: its spool is free for the next writer
            return
        waited = self.loop.join(timeout_s)
        if waited is not None:  # the thread is stuck in the database
            log.error("the history writer did not finish in %.1f s (the database does not answer); "
                      "what it holds goes to the spool", waited)
            self.forwarder.abandon()
        if self._process is not None:
            self._process.close()
        if not (self.queue.abandoned or self.tally.failing):  # a failing or hung database: not asked again
            if not (self.queue.held or self.forwarder.waiting) and self._lease.held:
                self.writes.release_reservations()  # else not everything was written, or not ours
            try:
                self._lease.release()
            except Exception as e:  # the next hub takes it over once stale (or at once: this pid is gone)
                log.warning("could not release the history writer lease: %s", e)
        self._report()
        self.forwarder.close()

    def _report(self) -> None:
        """At stop: say what did not reach the database, and where it is."""
        waiting = self.forwarder.waiting
        if waiting:
            assert self.spool is not None
            log.warning("history: %d records could not be written to the database and wait in the spool "
                        "%s; they are written when the database answers (at the next start)",
                        waiting, self.spool.folder)
        lost = self.queue.held
        if lost:
            log.error("history: %d records were not recorded (the database did not answer%s)", lost,
                      "" if self.spool is not None else " and there is no spool")
        if self.tally.dropped:
            log.error("history: %d records were not recorded in all (queue or spool full, or the writer "
                      "lease lost)", self.tally.dropped + lost)

    def outcome(self) -> dict[str, int]:
        """What became of the records (for a stop report): written, waiting in the spool, not recorded."""
        t = self.tally
        return {"written": t.written, "spooled": self.forwarder.waiting,
                "lost": t.dropped + self.queue.held + t.failed_records}

    def flush(self, timeout_s: float = 30.0) -> bool:
        """Block until everything submitted so far is committed (tests, benchmarks, export)."""
        deadline = time.monotonic() + timeout_s
        t = self.tally
        target = t.submitted
        self.queue.wake.set()
        while t.accounted < target and time.monotonic() < deadline:
            if self.loop.thread is None:
                self.writes.write_pending(self.loop.urgent)
            time.sleep(0.002)
        return t.accounted >= target
