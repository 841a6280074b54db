"""Store and forward: the history writer's records moved to the spool and written back from it.

When the database cannot take the records (batches have failed for ``spill_after_s``, the hub
stops while they fail, ``hurry``, or the queue holds half its byte budget while they fail), what
the writer holds in memory moves to the spool on disk (``spill``; then it counts as durable and
the plane is told). Before anything newer is written, the spool is forwarded to the database,
oldest first (``forward``), a slice of ``FORWARD_SLICE_S`` at a time so that the thread still
looks at its lease, its queue and ``stop``; rows the database already has (written before a
crash, or by a thread ``stop`` left behind) are left out, and a segment goes once all of it is in.

The spool itself (its files, its bounds, its lock) is ``spool.py``'s; this piece only calls its
API (``open``, ``append``, ``head``, ``consumed``, ``close`` and its counters). Without a spool
(``spool=None``) nothing is spilled: ``spill`` keeps the records queued and says so.

Accounting: ``forwarded`` counts every record written from the spool (any run's); ``written``
only those handed out in this run (``Tally.mine``), so that ``flush`` waits for this run's.
While the spool holds anything, ``DatabaseState.forwarding`` says so: a resume that needs
history is refused rather than served with a gap.
"""

from __future__ import annotations

import logging
import time
from typing import Any

from wott_hub.events.record import Record

from .ahead import Given
from .batch_writer import BatchWriter
from .record_queue import RecordQueue
from .spool import Spool, SpoolRow
from .state import DatabaseState
from .storage import StorageWriter
from .tally import Tally

__all__ = ["FORWARD_SLICE_S", "StoreAndForward"]

log = logging.getLogger("wott_hub.history.writer")  # the writer's log, as before it was in pieces

FORWARD_SLICE_S = 1.0
"""Forwarding works this long before the thread looks at its lease, its queue and ``stop`` again."""


class StoreAndForward:
    def __init__(self, spool: Spool | None, storage: StorageWriter, queue: RecordQueue, tally: Tally,
                 batches: BatchWriter, db: DatabaseState) -> None:
        self.spool = spool
        self.storage = storage
        self.queue = queue
        self.tally = tally
        self.batches = batches
        self.db = db

    def open(self) -> None:
        """Take the spool (``Conflict`` if another process has it) and say what waits in it."""
        if self.spool is not None:
            self.spool.open()
            self.note()

    def close(self) -> None:
        if self.spool is not None:
            self.spool.close()

    @property
    def waiting(self) -> int:
        """Records waiting in the spool (0 without one)."""
        return self.spool.records if self.spool is not None else 0

    def note(self) -> None:
        """Tell readers whether history lacks records that wait in the spool (a resume then waits)."""
        sp = self.spool
        self.db.forwarding = (f"{sp.records} records wait in the spool {str(sp.folder)!r} to be written "
                              "to the database" if sp is not None and sp.records else "")

    def health(self) -> dict[str, Any]:
        """What waits in the spool: records, bytes, the age of the oldest, what went where."""
        sp = self.spool
        assert sp is not None
        oldest = sp.oldest_t_ns  # the age of what waits: since the oldest record was made
        return {"path": str(sp.folder), "records": sp.records, "bytes": sp.bytes, "maxBytes": sp.max_bytes,
                "oldestAgeS": None if oldest is None else round(max(0.0, (time.time_ns() - oldest) / 1e9), 3),
                "spooled": self.tally.spooled, "forwarded": self.tally.forwarded, "dropped": sp.dropped}

    # --- spilling ---------------------------------------------------------------------------

    def spill(self) -> None:
        """Move everything queued to the spool's tail (then it is durable: ``on_commit``)."""
        q = self.queue
        with q.lock:
            if q.abandoned or not len(q):
                return
            records = q.drain()
            if self.spill_records(records):
                q.settle(records)
            else:
                q.put_back(records)  # kept in memory (bounded by the queue's bounds)

    def spill_held(self) -> None:
        """The batches in the database's hands and the queue onto the spool (a batch committed after
        all is left out when the spool is forwarded); the thread does not put them back (``hurry``)."""
        q = self.queue
        with q.lock:
            if q.abandoned:
                return
            taken = q.inflight
            q.inflight = []
            held = [r for b in taken for r in b] + q.drain()
            if held and not self.spill_records(held):
                q.inflight = taken  # the disk refused: still held, reported at stop
                q.put_back(held[sum(len(b) for b in taken):])
            else:
                q.settle(held)

    def abandon(self) -> None:
        """``stop`` gave up on the thread (stuck in the database): the batches it holds and the queue
        go to the spool (a batch it commits after all is left out when the spool is forwarded)."""
        q = self.queue
        if not q.lock.acquire(timeout=2.0):
            q.abandoned = True
            return
        try:
            q.abandoned = True
            held = [r for b in q.inflight for r in b] + q.drain()
            q.inflight.clear()
            if held and not self.spill_records(held):
                q.hold(held)  # reported as not recorded
            else:
                q.settle(held)
        finally:
            q.lock.release()

    def spill_records(self, records: list[Record]) -> bool:
        """``records`` onto the spool (the queue's lock held); False if the disk refused them."""
        sp = self.spool
        if sp is None:
            return False
        t = self.tally
        try:
            payloads = self.storage.encode(records)
            rows: list[SpoolRow] = [(r.thing, r.seq, r.kind, r.name, r.t_ns, d)
                                    for r, d in zip(records, payloads, strict=True)]
            dropped = sp.append(rows)
        except Exception as e:
            log.error("history: cannot spool %d records: %s", len(records), e)
            return False
        t.spooled += len(records)
        self.note()
        if dropped:
            t.dropped += dropped
            log.error("history: the spool %s is full (%d bytes): its %d oldest records were dropped",
                      sp.folder, sp.max_bytes, dropped)
        tops: dict[str, int] = {}
        for r in records:
            tops[r.thing] = r.seq
        t.tell(tops)  # on disk: durable, as a commit is
        return True

    # --- forwarding -------------------------------------------------------------------------

    def forward(self) -> None:
        """Write the spool's oldest segments to the database (for ``FORWARD_SLICE_S`` at most), rows
        the database already has left out; a segment goes once all of it is in."""
        sp = self.spool
        assert sp is not None
        q = self.queue
        step = self.batches.batch_max
        until = time.monotonic() + FORWARD_SLICE_S
        while time.monotonic() < until and not q.abandoned:
            with q.lock:
                head = sp.head()
            if head is None:
                break
            seg, rows = head
            for i in range(0, len(rows), step):
                self.forward_rows(rows[i:i + step])
                if q.abandoned:
                    return
            with q.lock:
                sp.consumed(seg)
                self.note()
        self.note()

    def forward_rows(self, rows: list[SpoolRow]) -> None:
        """One batch of spooled rows into the database: those it has are left out, those of a Thing it
        does not know are counted as not recorded, the rest written (refused ones isolated)."""
        storage, t = self.storage, self.tally
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
                mine += t.mine(thing, seq)
                continue  # written before a crash, or by a thread stop() left behind
            batch.append(Record(thing, seq, kind, name, t_ns, ""))
            payloads.append(data)
        for thing, n in lost.items():  # cannot be: a Thing is registered before its first record
            t.failed_records += n
            t.last_refused = time.monotonic()
            t.last_error = (f"{n} spooled records of {thing!r} not recorded: the Thing is not in "
                            "the database")
            log.error("history: %s", t.last_error)
        if batch:
            before = t.written
            self.batches.write_isolating(batch, Given(payloads), requeue=False)
            wrote = t.written - before
            t.forwarded += wrote
            t.written = before + min(wrote, sum(t.mine(r.thing, r.seq) for r in batch))
        t.written += mine
