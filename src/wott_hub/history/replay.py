"""Replay a recorded range as live records, with the original timing scaled: play, in one place.

The replay re-emits each record as read (``Record``: its Thing, seq, affordance and payload,
the JSON text as stored; its ``t_ns`` the time it is emitted) at
``start + (t - t_first) / speed``; ``speed=0`` emits as fast as possible.
Pages are read in a worker thread one page ahead, so reading never delays
emission. With ``loop`` the range starts again after its end, one mean record
interval later.

Like ``ros2 bag play``: ``names`` keeps only those affordances (the topic filter),
several Things replay together on one time base (``merge.py``: the order in which
they were recorded, whatever their rates), and ``offset_s`` starts that many seconds
into the range (each loop cycle starts there again).

A ``Replayer`` runs in a task of its own (``start``/``stop``, ``state``) or is awaited
(``run``); what the records become (the hub's replay Things: ``hub/replay.py``) is its
``emit``'s business.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from collections.abc import Iterator, Sequence

from wott_hub.errors import InvalidInput
from wott_hub.events.record import Record
from wott_hub.types import Emit

from .merge import merged_pages
from .storage import Columns, StorageReader
from .times import MAX_NS

__all__ = ["Replayer"]


class Replayer:
    def __init__(self, reader: StorageReader, thing: str | Sequence[str], *, t_from_ns: int | None = None,
                 t_to_ns: int | None = None, speed: float = 1.0, loop: bool = False,
                 names: list[str] | None = None, page: int = 20_000, offset_s: float = 0.0) -> None:
        if not (speed >= 0 and math.isfinite(speed)):  # nan and inf too: they would never emit
            raise InvalidInput(f"speed must be a finite number >= 0 (0: as fast as possible), got {speed}")
        if not (isinstance(offset_s, int | float) and math.isfinite(offset_s) and offset_s >= 0):
            raise InvalidInput(f"offset must be a finite number of seconds >= 0, got {offset_s!r}")
        self.reader = reader
        self.things = [thing] if isinstance(thing, str) else list(dict.fromkeys(thing))
        if not self.things:
            raise InvalidInput("replay needs at least one recorded device")
        self.t_from_ns = t_from_ns
        self.t_to_ns = t_to_ns
        self.offset_ns = int(offset_s * 1e9)
        self.speed = speed
        self.loop = loop
        self.names = names or None
        self.page = page
        self.emitted = 0
        self.cycles = 0
        self.task: asyncio.Task[None] | None = None
        self.ended = False

    @property
    def state(self) -> str:
        """"running" (started or about to be), then "ended" (the range played, or stopped)."""
        return "ended" if self.ended else "running"

    def start(self, emit: Emit, *, name: str | None = None) -> asyncio.Task[None]:
        """``run`` in a task of its own (``name``d), until the range ends (or ``stop``)."""

        async def play() -> None:
            try:
                await self.run(emit)
            finally:
                self.ended = True

        self.task = asyncio.create_task(play(), name=name)
        return self.task

    async def stop(self) -> None:
        """Cancel the task ``start`` made and wait for it to end."""
        task = self.task
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task

    def _range(self) -> tuple[int | None, int | None]:
        """The [from, to] actually read once the offset is applied (it counts from ``t_from_ns``, or
        from the first record of any of the Things when that is open)."""
        lo, hi = self.t_from_ns, self.t_to_ns
        if not self.offset_ns:
            return lo, hi
        start = lo if lo is not None else self.reader.first_time(self.things, None)
        if start is None:  # nothing recorded: the range stays empty either way
            return lo, hi
        return min(start + self.offset_ns, MAX_NS), hi  # past 2262 is past anything recorded

    def _pages(self, lo: int | None, hi: int | None) -> Iterator[Columns | list[Record]]:
        """One Thing: its pages as ``Columns`` (a ``Record`` is made as each is emitted: cheaper than a
        page of them, ``storage.Columns``); several: their records merged by time."""
        if len(self.things) == 1:
            return self.reader.columns(self.things[0], lo, hi, self.names, self.page)
        return merged_pages(self.reader, self.things, lo, hi, self.names, self.page)

    async def run(self, emit: Emit, stop: asyncio.Event | None = None) -> int:
        """Emit until the range ends (or forever with ``loop``, until ``stop`` is set)."""
        loop = asyncio.get_running_loop()
        lo, hi = await asyncio.to_thread(self._range)
        now = time.time_ns
        thing = self.things[0]
        clock0: float | None = None
        while stop is None or not stop.is_set():
            pages = self._pages(lo, hi)
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
                else:
                    count, t0, t1 = len(page), page[0].t_ns, page[-1].t_ns
                if t_first is None:
                    t_first = t0
                    if clock0 is None:
                        clock0 = loop.time()
                if self.speed == 0:  # as fast as possible: no clock, a yield every 2,000 records
                    for done in range(0, count, 2000):
                        end = done + 2000
                        if isinstance(page, Columns):
                            for seq, kind, name, data in zip(page.seqs[done:end], page.kinds[done:end],
                                                             page.names[done:end], page.data[done:end],
                                                             strict=True):
                                emit(Record(thing, seq, kind, name, now(), data))
                        else:
                            for rec in page[done:end]:
                                rec.t_ns = now()
                                emit(rec)
                        await asyncio.sleep(0)
                        if stop is not None and stop.is_set():
                            nxt.cancel()
                            self.emitted += min(count, done + 2000)
                            return self.emitted
                    n_cycle += count
                    self.emitted += count
                    t_last = t1
                    continue
                assert clock0 is not None  # set with t_first, on this page or an earlier one
                for rec in page.records(thing) if isinstance(page, Columns) else page:
                    t_ns = rec.t_ns
                    due = clock0 + (t_ns - t_first) / 1e9 / self.speed
                    delay = due - loop.time()
                    if delay > 0.0002:
                        await asyncio.sleep(delay)
                        if stop is not None and stop.is_set():
                            nxt.cancel()
                            return self.emitted
                    rec.t_ns = now()
                    emit(rec)
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
