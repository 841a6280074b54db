"""How the history writer's batches are written: one transaction each, refused records isolated.

A batch is taken off the queue (``RecordQueue.take``) and written in one transaction that also
moves each of its Things' sequence reservation ahead (``RESERVE``); the watermarks it commits are
told to the event plane (``Tally.tell``). Where it is written:
- by the batch process (``batch_process.py``) while the writer keeps up (fewer than
  ``CATCH_UP`` records wait behind the batch): off the GIL of the process that submits;
- else here, in the writer's thread, and with a storage that ``overlaps`` (PostgreSQL) the next
  batch is taken and encoded meanwhile (``ahead.Ahead``) when at least ``AHEAD_MIN`` wait.

Contract (``write_isolating``): a batch the database refuses for its *data* (``RecordRefused``)
is split in halves until the refused records are isolated (log2(n) extra transactions per refused
record): every other record is written, in seq order; each refused one is counted, named in
``last_error``, given up on and told to the plane like a written one. Any other error puts every
record not yet written back at the head of the queue (then the next batch's, taken ahead), to be
retried first, and is raised to the thread (which backs off, or spools).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

from wott_hub.errors import RecordRefused
from wott_hub.events.record import Record

from .ahead import Ahead, Given
from .batch_process import BatchProcess
from .db_errors import driver_message
from .lease import Lease
from .record_queue import RecordQueue
from .storage import Prepared, Step, StorageWriter
from .tally import Tally

__all__ = ["AHEAD_MIN", "BEHIND", "CATCH_UP", "RESERVE", "BatchWriter"]

log = logging.getLogger("wott_hub.history.writer")  # the writer's log, as before it was in pieces

RESERVE = 1 << 20
"""How far ahead of its last committed record a Thing's sequence is reserved.

Records handed out but not yet committed stay below the reservation as long
as fewer than this many of one Thing wait in the queue (``queue_max`` keeps it so)."""

AHEAD_MIN = 1_000
"""Records that must wait behind a batch for the writer to take the next batch and encode it
while PostgreSQL writes this one: below that the writer is keeping up."""
CATCH_UP = 20_000
"""Records waiting behind a batch from which the writer's thread writes it itself though it has a
batch process: catching up matters more then than the event loop's share of the GIL. The
process writes 29,000-54,000 records/s (the hand-over costs ~8 µs a record: pickling the
records, the pipe, unpickling them), the thread 67,000-82,000 (docs/history.md); a hub keeping
up has ~770 waiting per 50 ms batch at 64 devices x 120 Hz."""
BEHIND = 2_000
"""Records waiting after a batch from which the writer writes the next one at once rather than
at its next wake (``interval_s``). Below that it is keeping up, and a batch of what arrived while
the last one was written (~65 records at 32 devices x 120 Hz) would cost the batch process ~3x
as much a record as one wake's worth (~1,150 at 100 ms): encoding a batch and committing it have
fixed costs (measured: 96 against 31 µs of the process's CPU a frame; docs/history.md)."""


class BatchWriter:
    def __init__(self, storage: StorageWriter, queue: RecordQueue, tally: Tally, lease: Lease, *,
                 batch_max: int, process: BatchProcess | None) -> None:
        self.storage = storage
        self.queue = queue
        self.tally = tally
        self.lease = lease
        self.batch_max = batch_max
        self.process = process
        self.reserved: dict[str, int] = {}
        """Each Thing's sequence reservation in the database (registered this run)."""

    def write_pending(self, urgent: Callable[[], bool]) -> None:
        """Write the queue batch by batch, each by the batch process if there is one and fewer than
        ``CATCH_UP`` records wait behind it, else here. Here, with a storage that ``overlaps``
        (PostgreSQL), while more records wait, the next batch is taken too and its payloads
        encoded (``codec.py``, Python: about as costly as the server's work) a slice at a time,
        then its rows prepared, while the server works through this batch's data: the two
        costs overlap instead of adding up. In this thread, between its socket writes, not in
        another one: a second thread would hold the GIL while the socket waits for more data,
        and each hand-over takes up to the interpreter's 5 ms switch interval (measured: no
        faster than without overlap). ``urgent``: a stop or a hurry is asked for (then what
        came in meanwhile is written now, not at the next wake)."""
        q = self.queue
        batch: list[Record] = []
        encoded: Ahead | None = None
        while (batch or len(q)) and not self.lease.lost and not q.abandoned:
            if not batch:
                batch, encoded = q.take(), None
                if not batch:
                    break
            process = self.process if encoded is None and len(q) < CATCH_UP else None
            ahead = Ahead(self.storage, q.take()) \
                if self.storage.overlaps and process is None and len(q) >= AHEAD_MIN else None
            self.write_isolating(batch, encoded, ahead, process)
            batch, encoded = ([], None) if ahead is None else (ahead.batch, ahead)
            if not batch and len(q) < BEHIND and not urgent():
                break  # keeping up: what came in meanwhile waits for the next wake, a batch of its own
        if batch:  # taken ahead when the lease was lost: back in the queue, given up with it
            q.requeue(batch, [batch])

    def write_isolating(self, batch: list[Record], encoded: Ahead | Given | None = None,
                        ahead: Ahead | None = None, process: BatchProcess | None = None, *,
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
                    self.write(part, payloads, None if ahead is None else ahead.step,
                               prepared if part is batch else None, process)
                except RecordRefused as e:
                    if len(part) == 1:
                        self.refuse(part[0], e)
                        continue
                    mid = len(part) // 2
                    todo.append((part[mid:], None if payloads is None else payloads[mid:]))
                    todo.append((part[:mid], None if payloads is None else payloads[:mid]))
        except Exception:
            if requeue:
                left = part + [r for p, _ in reversed(todo) for r in p]
                if ahead is not None:
                    left += ahead.batch
                self.queue.requeue(left, [batch] if ahead is None else [batch, ahead.batch])  # retried first
            raise
        if requeue:
            self.queue.done(batch)

    def refuse(self, rec: Record, e: Exception) -> None:
        """``rec`` alone was refused for its data: given up on, counted, named, told as committed."""
        t = self.tally
        t.failed_records += 1
        t.last_refused = time.monotonic()
        t.last_error = f"{rec.thing} seq {rec.seq} not recorded: {driver_message(e)}"
        log.error("history: %s", t.last_error)
        t.give_up(rec.thing, rec.seq)
        t.committed[rec.thing] = max(t.committed.get(rec.thing, 0), rec.seq)
        t.tell({rec.thing: rec.seq})

    def write(self, batch: list[Record], payloads: list[bytes] | None = None, meanwhile: Step | None = None,
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
                   if thing in self.reserved  # forwarded from the spool: its registration reserves)
                   and top > self.reserved[thing] - RESERVE // 2 - 2 * self.batch_max}
        if process is not None:
            process.write(batch, keys, reserve)
        else:
            assert prepared is not None
            storage.write(prepared, reserve, meanwhile)
        self.reserved.update(reserve)
        t = self.tally
        t.committed.update(tops)
        t.written += len(batch)
        t.batches += 1
        t.last_batch_s = time.perf_counter() - t0
        t.tell(tops)

    def release_reservations(self) -> None:
        """After a clean stop, the next run continues right after the last committed seq."""
        try:
            self.storage.release({t: s for t, s in self.tally.committed.items() if t in self.reserved})
        except Exception:
            log.exception("could not release sequence reservations (the next run skips ahead)")
        else:
            self.reserved.update(self.tally.committed)
