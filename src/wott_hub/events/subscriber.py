"""A consumer of the event plane: an SSE connection, a WebSocket subscription...

Publishing never waits for a consumer: ``push`` appends to the subscriber's
queue and wakes its task, which sends everything pending in one write (under
load, many records per write: throughput; when idle, one: latency). A consumer
that falls ``max_pending`` records behind is cut off instead of slowing the
hub down or growing memory without bound; an SSE client then reconnects with
``Last-Event-ID`` and is served the rest from history, so it loses nothing.
"""

from __future__ import annotations

import asyncio
from collections import deque
from collections.abc import AsyncIterator, Callable

from .record import Record

__all__ = ["Interest", "Subscriber"]

Interest = tuple[int, str | None]
"""(kind, name): name None means every affordance of that kind."""


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
        self._backfill: AsyncIterator[list[Record]] | None = None
        self._on_close = on_close

    def wants(self, rec: Record) -> bool:
        kind, name = self.interest
        return rec.kind == kind and (name is None or rec.name == name)

    def push(self, rec: Record) -> None:
        if self.closed:
            return
        if len(self.pending) >= self.max_pending:
            self.overflowed = True
            self.close()
            return
        self.pending.append(rec)
        wake = self._wake
        if wake is not None and not wake.done():
            wake.set_result(None)

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        self._on_close(self)
        wake = self._wake
        if wake is not None and not wake.done():
            wake.set_result(None)

    async def batches(self) -> AsyncIterator[list[Record]]:
        """Backfilled records (resume) first, then live ones, in seq order, each once."""
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
                await self._wake
                self._wake = None
                continue
            batch = list(self.pending)
            self.pending.clear()
            if batch[0].seq <= self.last_seq:
                batch = [r for r in batch if r.seq > self.last_seq]
                if not batch:
                    continue
            self.last_seq = batch[-1].seq
            yield batch
