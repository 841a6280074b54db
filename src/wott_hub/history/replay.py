"""Replay a recorded range as live records, with the original timing scaled.

The replay re-emits each record's payload unchanged (the JSON text as stored)
at ``start + (t - t_first) / speed``; ``speed=0`` emits as fast as possible.
Pages are read in a worker thread one page ahead, so reading never delays
emission. With ``loop`` the range starts again after its end, one mean record
interval later.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable

from .reader import HistoryReader

__all__ = ["Replayer"]

Emit = Callable[[int, str, int, str], None]
"""emit(kind, name, t_ns, data)"""


class Replayer:
    def __init__(self, reader: HistoryReader, thing: str, *, t_from_ns: int | None = None,
                 t_to_ns: int | None = None, speed: float = 1.0, loop: bool = False,
                 names: list[str] | None = None, page: int = 20_000) -> None:
        if not speed >= 0:
            raise ValueError(f"speed must be >= 0 (0: as fast as possible), got {speed}")
        self.reader = reader
        self.thing = thing
        self.t_from_ns = t_from_ns
        self.t_to_ns = t_to_ns
        self.speed = speed
        self.loop = loop
        self.names = names
        self.page = page
        self.emitted = 0
        self.cycles = 0

    async def run(self, emit: Emit, stop: asyncio.Event | None = None) -> int:
        """Emit until the range ends (or forever with ``loop``, until ``stop`` is set)."""
        loop = asyncio.get_running_loop()
        clock0: float | None = None
        while stop is None or not stop.is_set():
            pages = self.reader.pages(self.thing, self.t_from_ns, self.t_to_ns, self.names, self.page)
            nxt = asyncio.ensure_future(asyncio.to_thread(next, pages, None))
            t_first = t_last = None
            n_cycle = 0
            while True:
                rows = await nxt
                if rows is None:
                    break
                nxt = asyncio.ensure_future(asyncio.to_thread(next, pages, None))
                for _seq, t_ns, kind, name, data in rows:
                    if t_first is None:
                        t_first = t_ns
                        if clock0 is None:
                            clock0 = loop.time()
                    if self.speed > 0:
                        due = clock0 + (t_ns - t_first) / 1e9 / self.speed
                        delay = due - loop.time()
                        if delay > 0.0002:
                            await asyncio.sleep(delay)
                            if stop is not None and stop.is_set():
                                nxt.cancel()
                                return self.emitted
                    elif n_cycle % 2000 == 1999:
                        await asyncio.sleep(0)
                    emit(kind, name, time.time_ns(), data)
                    t_last = t_ns
                    n_cycle += 1
                    self.emitted += 1
            self.cycles += 1
            if not self.loop or t_first is None:
                return self.emitted
            span = (t_last - t_first) / 1e9
            gap = span / max(n_cycle - 1, 1)
            if self.speed > 0:
                clock0 += (span + gap) / self.speed
        return self.emitted
