"""The history writer's queue: records waiting for their batch, bounded in records and in bytes.

The event loop only appends (``offer``: no lock, no I/O); the writer's thread takes batches off
the head (``take``) and keeps each in ``inflight`` until it is written (``done``) or put back at
the head to be retried first (``requeue``). ``lock`` serialises the hand-overs between the
writer's thread, ``stop`` and ``hurry`` (store and forward holds it while it moves the queue to
the spool); ``abandoned`` is set once ``stop`` gave up waiting for the thread: from then on the
thread must not touch the queue.

Bounded twice: ``max_records`` keeps every Thing's waiting records below its sequence
reservation (``batch_writer.RESERVE``); ``max_bytes`` keeps the memory bounded whatever a record
weighs (a raw camera image is ~250 kB, a taxel packet ~1 kB: 524,288 images would be over
100 GB). Beyond either, ``offer`` refuses and the writer counts the record as dropped. The bytes
are an estimate (``record_bytes``: the payload's text, a skin packet's arrays, a fixed share for
the objects), counted on the event loop's side when a record comes in and under ``lock`` when
it leaves the writer's memory (``settle``: written, spooled or given up), so neither side needs
the other's lock. A record taken off for a batch or a spill still counts until then: else, while
a failing batch is retried or a spill is encoded, the queue would fill its budget again and the
records put back would take it past (measured on a full disk: 18 MB queued for 16).
"""

from __future__ import annotations

import threading
import time
from collections import deque

from wott_hub.events.record import OBJECT_BYTES as _OBJECT_BYTES
from wott_hub.events.record import Record, record_bytes

__all__ = ["QUEUE_BYTES", "RecordQueue", "record_bytes"]

QUEUE_BYTES = 256_000_000
"""The default byte budget of the queue (``history_queue_mb``): at 7.5 MB/s of raw images a
34 s outage before the spool takes the records, ~5 minutes of a 32-device hub's taxel packets."""


class RecordQueue:
    def __init__(self, *, max_records: int, max_bytes: int, batch_max: int) -> None:
        self.max_records = max_records
        self.max_bytes = max_bytes
        self.batch_max = batch_max
        self.wake = threading.Event()
        """Set when a batch is full (or by a stop, a hurry, a flush): the thread writes now."""
        self.lock = threading.Lock()
        self.inflight: list[list[Record]] = []  # batches taken from the queue, not yet done
        self.taken_at = 0.0  # time.monotonic() the last batch was taken
        self.abandoned = False  # stop() gave up waiting: the thread must not touch queue or spool
        self._q: deque[Record] = deque()
        self._added = 0  # bytes offered (the event loop's side)
        self._removed = 0  # bytes settled: written, spooled or given up (under ``lock``)

    def __len__(self) -> int:
        return len(self._q)

    @property
    def bytes(self) -> int:
        """The estimated bytes the writer holds (``record_bytes``): queued, in flight, being spilled."""
        return self._added - self._removed

    def offer(self, rec: Record) -> bool:
        """Append ``rec``; False (nothing done) if the queue is full in records or in bytes."""
        q = self._q
        size = len(rec.data) + _OBJECT_BYTES  # record_bytes, inline: this is the event loop's time
        skin = rec.skin
        if skin is not None:
            size += skin.ids.nbytes + skin.intensity.nbytes
        if len(q) >= self.max_records or self._added - self._removed + size > self.max_bytes:
            return False
        q.append(rec)
        self._added += size
        if len(q) >= self.batch_max:
            self.wake.set()
        return True

    def _pop(self, n: int) -> list[Record]:
        q = self._q
        return [q.popleft() for _ in range(n)]

    def take(self) -> list[Record]:
        """The next batch off the queue, kept in ``inflight`` until it is done."""
        with self.lock:
            if self.abandoned:
                return []
            batch = self._pop(min(len(self._q), self.batch_max))
            if batch:
                self.inflight.append(batch)
                self.taken_at = time.monotonic()
            return batch

    def drain(self) -> list[Record]:
        """Everything queued, taken off (``lock`` held; a record submitted meanwhile stays queued); its
        bytes count until ``settle`` (or ``put_back``)."""
        return self._pop(len(self._q))

    def put_back(self, records: list[Record]) -> None:
        """``records`` back at the head of the queue, in their order (``lock`` held)."""
        self._q.extendleft(reversed(records))  # still counted: never settled

    def hold(self, records: list[Record]) -> None:
        """``records`` at the tail, past the bounds (``lock`` held): kept only to be reported at stop."""
        self._q.extend(records)

    def settle(self, records: list[Record]) -> None:
        """``records``, taken off, have left the writer's memory (written, spooled, given up): their
        bytes no longer count (``lock`` held)."""
        self._removed += sum(map(record_bytes, records))

    def done(self, *batches: list[Record]) -> None:
        with self.lock:
            for b in batches:
                if any(x is b for x in self.inflight):
                    self.inflight = [x for x in self.inflight if x is not b]
                    self.settle(b)

    def requeue(self, records: list[Record], batches: list[list[Record]]) -> None:
        """``records`` (what is left of ``batches``) back at the head of the queue, retried first."""
        with self.lock:
            held = [x for x in self.inflight if any(x is b for b in batches)]
            self.inflight = [x for x in self.inflight if not any(x is b for b in batches)]
            gone = sum(record_bytes(r) for b in held for r in b)
            if not self.abandoned and len(held) == len(batches):  # else spooled already (stop, hurry)
                self.put_back(records)
                gone -= sum(map(record_bytes, records))
            self._removed += gone  # what of the batches was written

    @property
    def held(self) -> int:
        """Records not done with: queued or in flight (reported as not recorded at stop)."""
        return len(self._q) + sum(len(b) for b in self.inflight)
