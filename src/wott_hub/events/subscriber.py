"""A consumer of the event plane: an SSE connection, a WebSocket subscription...

Publishing never waits for a consumer. While a consumer waits in ``batches``
with nothing pending, ``push`` writes a record itself through the consumer's
``direct`` writer, at once: waking the consumer's task instead would send it
only after everything else ready on the loop (at 32 devices, milliseconds).
Otherwise, or when the writer cannot take it now (its socket backed up),
``push`` queues the record and wakes the task, which sends everything pending
in one write: under load many records per write (``DIRECT_RATE`` bounds the
writes a busy stream makes one by one), and no record overtakes a queued one.
A consumer that falls ``max_pending`` records behind is cut off instead of
slowing the hub down or growing memory without bound; an SSE client then
reconnects with ``Last-Event-ID`` and is served the rest from history, so it
loses nothing. Cut off means disconnected (issue 48): its pending records are
let go at once and its ``cut`` callback (the consumer's socket close) runs, so
a client that stopped reading cannot keep its task waiting on a backed-up
socket with a batch and the socket's buffer pinned in memory.
"""

from __future__ import annotations

import asyncio
from collections import deque
from collections.abc import AsyncIterator, Callable

from wott_hub.types import Direct

from .bucket import Bucket
from .record import Record

__all__ = ["DIRECT_BURST", "DIRECT_RATE", "Interest", "Subscriber"]

Interest = tuple[int, str | None]
"""(kind, name): name None means every affordance of that kind."""

DIRECT_RATE = 1000.0
DIRECT_BURST = 8.0
"""How many records a subscriber writes itself: ``DIRECT_RATE`` a second on average, up to
``DIRECT_BURST`` back to back (a device catching up yields a few frames at once); beyond that a
record is queued and goes with the rest of the loop turn's, in one write."""


class Subscriber:
    def __init__(self, thing: str, interest: Interest, max_pending: int,
                 on_close: Callable[[Subscriber], None]) -> None:
        self.thing = thing
        self.interest = interest
        self.max_pending = max_pending
        self.pending: deque[Record] = deque()
        self.closed = False
        self.overflowed = False
        self.last_seq = -1  # the last seq handed to the consumer (de-duplicates backfill vs live)
        self.gap: tuple[int, int] | None = None  # (after, first available) when history cannot fill
        self._wake: asyncio.Future[None] | None = None
        self._direct: Direct | None = None  # set while the consumer waits with nothing pending
        self._bucket = Bucket(DIRECT_RATE, DIRECT_BURST)
        self._backfill: AsyncIterator[list[Record]] | None = None
        self._on_close = on_close
        self.cut: Callable[[], None] | None = None  # the consumer's disconnect, run when it overflows

    def wants(self, rec: Record) -> bool:
        kind, name = self.interest
        return rec.kind == kind and (name is None or rec.name == name)

    def push(self, rec: Record) -> None:
        if self.closed:
            return
        direct = self._direct
        if direct is not None and self._bucket.take():
            try:
                written = direct(rec)
            except Exception:  # a consumer's bug must not reach the publisher: queue it
                written = False
            if written:
                self.last_seq = rec.seq
                return
        if len(self.pending) >= self.max_pending:
            self.overflow()
            return
        self.pending.append(rec)
        self._direct = None  # the consumer sends what is queued first: no record may overtake it
        wake = self._wake
        if wake is not None and not wake.done():
            wake.set_result(None)

    def overflow(self) -> None:
        """Cut off: the pending records let go, the subscription closed, the consumer disconnected."""
        self.overflowed = True
        self.pending.clear()
        self.close()
        cut, self.cut = self.cut, None
        if cut is not None:
            try:
                cut()
            except Exception:  # a consumer's bug must not reach the publisher
                pass

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        self._on_close(self)
        wake = self._wake
        if wake is not None and not wake.done():
            wake.set_result(None)

    async def batches(self, direct: Direct | None = None) -> AsyncIterator[list[Record]]:
        """Backfilled records (resume) first, then live ones, in seq order, each once; while the
        consumer waits, ``push`` may write a record itself with ``direct`` (module docstring)."""
        if self._backfill is not None:
            async for batch in self._backfill:
                out = [r for r in batch if r.seq > self.last_seq]
                if out:
                    self.last_seq = out[-1].seq
                    yield out
                if self.closed:
                    return
            self._backfill = None
        loop = asyncio.get_running_loop()
        while not self.closed:
            if not self.pending:
                self._wake = loop.create_future()
                self._direct = direct
                try:
                    await self._wake
                finally:
                    self._direct = self._wake = None
                continue
            batch = list(self.pending)
            self.pending.clear()
            if batch[0].seq <= self.last_seq:
                batch = [r for r in batch if r.seq > self.last_seq]
                if not batch:
                    continue
            self.last_seq = batch[-1].seq
            yield batch
