"""Expiry (WoT Discovery 7.3.1.2): when each TD's registration runs out, and the task that purges.

A heap of (``expires`` as a timestamp, id); an entry is pushed each time a TD is written with an
``expires``, and never removed in place: a TD deleted or re-registered since leaves a stale entry,
recognised when it comes due (its current ``expires`` differs) and skipped. The purge itself (a
delete and its ``thing_deleted`` event) is the directory's; this module says what is due and
calls it every ``purge_interval`` s.
"""

from __future__ import annotations

import asyncio
import heapq
import logging
from collections.abc import Awaitable, Callable, Iterator

from .registration import Enriched

__all__ = ["Expiry"]

log = logging.getLogger("wott_directory")


class Expiry:
    def __init__(self) -> None:
        self._heap: list[tuple[float, str]] = []
        self._task: asyncio.Task[None] | None = None

    def add(self, thing_id: str, rec: Enriched) -> None:
        """``rec`` was stored: it expires at its ``expires`` (if any)."""
        if rec.expires is not None:
            heapq.heappush(self._heap, (rec.expires.timestamp(), thing_id))

    def due(self, now: float) -> bool:
        return bool(self._heap) and self._heap[0][0] <= now

    def pop_due(self, now: float, current: Callable[[str], Enriched | None]) -> Iterator[str]:
        """The ids whose registration ran out by ``now`` (``current``: the TD stored under an id now)."""
        heap = self._heap
        while heap and heap[0][0] <= now:
            stamp, thing_id = heapq.heappop(heap)
            rec = current(thing_id)
            if rec is None or rec.expires is None or rec.expires.timestamp() != stamp:
                continue  # deleted or re-registered since: a stale heap entry
            yield thing_id

    def start(self, purge: Callable[[], Awaitable[object]], interval_s: float) -> None:
        """Call ``purge`` every ``interval_s`` s until ``stop``."""
        self._task = asyncio.create_task(self._loop(purge, interval_s))

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            try:
                await self._task
            except asyncio.CancelledError:
                pass
            self._task = None

    @staticmethod
    async def _loop(purge: Callable[[], Awaitable[object]], interval_s: float) -> None:
        while True:
            await asyncio.sleep(interval_s)
            try:
                await purge()
            except Exception:  # a database hiccup must not end purging for good
                log.exception("purging expired TDs failed; retrying in %.1f s", interval_s)
