"""Records of several recorded Things on one time base: the rosbag2-style multi-source read.

Replay and MCAP export read each Thing's range in pages (``StorageReader.pages``) and
merge them by time here, so two devices recorded side by side come out in the order they
were recorded, whatever their rates. Within one Thing, time order is seq order; records of
different Things at the same nanosecond come out in the order of ``things``.

A Thing named twice is read once (``historyExport`` with one id repeated 10,000 times read it
10,000 times over, a page of each in memory at once: 11.5 GB, issue 48), and the pages held
while merging stay near ``page`` records in all: each Thing's stream reads ``page / len(things)``
at a time (at least ``MIN_STREAM_PAGE``).
"""

from __future__ import annotations

import heapq
from collections.abc import Iterator, Sequence
from itertools import chain
from operator import attrgetter
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from wott_hub.events.record import Record

    from .storage import StorageReader

__all__ = ["MIN_STREAM_PAGE", "merged_pages"]

_TIME = attrgetter("t_ns")
MIN_STREAM_PAGE = 500


def merged_pages(reader: StorageReader, things: Sequence[str], t_from_ns: int | None = None,
                 t_to_ns: int | None = None, names: list[str] | None = None,
                 page: int = 20_000) -> Iterator[list[Record]]:
    """Pages of the records of every Thing in ``things`` (each once), in time order (one Thing: its
    pages as read)."""
    things = list(dict.fromkeys(things))
    if len(things) == 1:
        yield from reader.pages(things[0], t_from_ns, t_to_ns, names, page)
        return
    each = max(page // max(len(things), 1), MIN_STREAM_PAGE)
    streams = [chain.from_iterable(reader.pages(th, t_from_ns, t_to_ns, names, each)) for th in things]
    out: list[Record] = []
    for rec in heapq.merge(*streams, key=_TIME):
        out.append(rec)
        if len(out) >= page:
            yield out
            out = []
    if out:
        yield out
