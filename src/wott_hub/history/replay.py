"""Replay a recorded range as live records, with the original timing scaled.

The replay re-emits each record's payload unchanged (the JSON text as stored)
at ``start + (t - t_first) / speed``; ``speed=0`` emits as fast as possible.
Pages are read in a worker thread one page ahead, so reading never delays
emission. With ``loop`` the range starts again after its end, one mean record
interval later.

Like ``ros2 bag play``: ``names`` keeps only those affordances (the topic filter),
several Things replay together on one time base (``merge.py``: the order in which
they were recorded, whatever their rates), and ``offset_s`` starts that many seconds
into the range (each loop cycle starts there again).
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Iterator, Sequence
from itertools import islice, repeat
from typing import Any

from wott_hub.errors import InvalidInput
from wott_hub.types import Emit, EmitFrom

from .merge import Row, merged_pages, resolve_range
from .reader import Columns, HistoryReader

__all__ = ["Replayer"]


class Replayer:
    def __init__(self, reader: HistoryReader, thing: str | Sequence[str], *, t_from_ns: int | None = None,
                 t_to_ns: int | None = None, speed: float = 1.0, loop: bool = False,
                 names: list[str] | None = None, page: int = 20_000, offset_s: float = 0.0) -> None:
        if not (speed >= 0 and math.isfinite(speed)):  # nan and inf too: they would never emit
            raise InvalidInput(f"speed must be a finite number >= 0 (0: as fast as possible), got {speed}")
        if not (isinstance(offset_s, int | float) and math.isfinite(offset_s) and offset_s >= 0):
            raise InvalidInput(f"offset must be a finite number of seconds >= 0, got {offset_s!r}")
        self.reader = reader
        self.things = [thing] if isinstance(thing, str) else list(thing)
        if not self.things:
            raise InvalidInput("replay needs at least one recorded device")
        self.thing = self.things[0]
        self.t_from_ns = t_from_ns
        self.t_to_ns = t_to_ns
        self.offset_ns = int(offset_s * 1e9)
        self.speed = speed
        self.loop = loop
        self.names = names or None
        self.page = page
        self.emitted = 0
        self.cycles = 0

    async def run(self, emit: Emit, stop: asyncio.Event | None = None) -> int:
        """Emit until the range ends (or forever with ``loop``, until ``stop`` is set)."""
        if len(self.things) == 1:
            return await self._run(emit, None, stop)
        return await self._run(None, lambda _thing, k, n, t, d: emit(k, n, t, d), stop)

    async def run_from(self, emit: EmitFrom, stop: asyncio.Event | None = None) -> int:
        """``run`` for several Things: ``emit`` is told which Thing each record belongs to."""
        return await self._run(None, emit, stop)

    def _pages(self, lo: int | None, hi: int | None, tagged: bool) -> Iterator[Columns | list[Row]]:
        if tagged:
            return merged_pages(self.reader, self.things, lo, hi, self.names, self.page)
        return self.reader.columns(self.thing, lo, hi, self.names, self.page)

    async def _run(self, emit: Emit | None, emit_from: EmitFrom | None, stop: asyncio.Event | None) -> int:
        loop = asyncio.get_running_loop()
        lo, hi = await asyncio.to_thread(resolve_range, self.reader, self.things, self.t_from_ns,
                                         self.t_to_ns, self.offset_ns)
        tagged = emit_from is not None
        now = time.time_ns
        clock0: float | None = None
        while stop is None or not stop.is_set():
            pages = self._pages(lo, hi, tagged)
            nxt = asyncio.ensure_future(asyncio.to_thread(next, pages, None))
            t_first = t_last = None
            n_cycle = 0
            while True:
                page = await nxt
                if page is None:
                    break
                # the next page is read (in a worker thread) while this one is emitted
                nxt = asyncio.ensure_future(asyncio.to_thread(next, pages, None))
                if isinstance(page, Columns):
                    count, t0, t1 = len(page.data), page.times[0], page.times[-1]
                    records: Iterator[tuple[Any, ...]] = zip(repeat(None), page.times, page.kinds, page.names,
                                                             page.data, strict=False)  # repeat: endless
                else:
                    count, t0, t1 = len(page), page[0][2], page[-1][2]
                    records = ((thing, t, kind, name, data) for thing, _seq, t, kind, name, data in page)
                if t_first is None:
                    t_first = t0
                    if clock0 is None:
                        clock0 = loop.time()
                if self.speed == 0:  # as fast as possible: no clock, a yield every 2,000 records
                    if emit is not None:  # one Thing: its columns zipped, no tuple per record
                        assert isinstance(page, Columns)
                        records = zip(page.kinds, page.names, page.data, strict=True)
                    for done in range(2000, count + 2000, 2000):
                        if emit is not None:
                            for kind, name, data in islice(records, 2000):
                                emit(kind, name, now(), data)
                        else:
                            assert emit_from is not None
                            for thing, _t, kind, name, data in islice(records, 2000):
                                emit_from(thing, kind, name, now(), data)
                        await asyncio.sleep(0)
                        if stop is not None and stop.is_set():
                            nxt.cancel()
                            self.emitted += min(count, done)
                            return self.emitted
                    n_cycle += count
                    self.emitted += count
                    t_last = t1
                    continue
                for thing, t_ns, kind, name, data in records:
                    due = clock0 + (t_ns - t_first) / 1e9 / self.speed
                    delay = due - loop.time()
                    if delay > 0.0002:
                        await asyncio.sleep(delay)
                        if stop is not None and stop.is_set():
                            nxt.cancel()
                            return self.emitted
                    if emit_from is not None:
                        emit_from(thing, kind, name, now(), data)
                    else:
                        assert emit is not None
                        emit(kind, name, now(), data)
                    t_last = t_ns
                    n_cycle += 1
                    self.emitted += 1
            self.cycles += 1
            if not self.loop or t_first is None or t_last is None or clock0 is None:
                return self.emitted
            span = (t_last - t_first) / 1e9
            gap = span / max(n_cycle - 1, 1)
            if self.speed > 0:
                clock0 += (span + gap) / self.speed
        return self.emitted
