"""Records of several recorded Things on one time base: the rosbag2-style multi-source read.

Replay and MCAP export read each Thing's range in pages (``HistoryReader.pages``) and
merge them by time here, so two devices recorded side by side come out in the order they
were recorded, whatever their rates. Within one Thing, time order is seq order; records of
different Things at the same nanosecond come out in the order of ``things``.

A range is [``t_from`` + ``offset``, ``t_to``]: ``offset`` seeks into the recording (ns
after ``t_from``, or after the first record of any of the Things when ``t_from`` is open).
"""

from __future__ import annotations

import heapq
from collections.abc import Iterator, Sequence
from typing import TYPE_CHECKING

import sqlalchemy as sa

from wott_hub.errors import InvalidInput

from .models import EventRow

if TYPE_CHECKING:
    from .reader import HistoryReader

__all__ = ["Row", "first_time", "merged_pages", "resolve_range"]

Row = tuple[str, int, int, int, str, str]
"""(thing, seq, t_ns, kind, name, data)"""

_E = EventRow.__table__


def first_time(reader: HistoryReader, things: Sequence[str], t_from_ns: int | None) -> int | None:
    """The earliest record time of any of ``things`` at or after ``t_from_ns`` (the time index)."""
    best = None
    for thing in things:
        key = reader.key(thing)
        if key is None:
            continue
        q = sa.select(sa.func.min(_E.c.t_ns)).where(_E.c.thing_key == key)
        if t_from_ns is not None:
            q = q.where(_E.c.t_ns >= t_from_ns)
        with reader.engine.connect() as conn:
            t = conn.execute(q).scalar()
        if t is not None and (best is None or t < best):
            best = t
    return best


def resolve_range(reader: HistoryReader, things: Sequence[str], t_from_ns: int | None,
                  t_to_ns: int | None, offset_ns: int = 0) -> tuple[int | None, int | None]:
    """The [from, to] actually read once ``offset_ns`` is applied (``InvalidInput`` if negative)."""
    if offset_ns < 0:
        raise InvalidInput(f"offset must be >= 0 s, got {offset_ns / 1e9:g}")
    if not offset_ns:
        return t_from_ns, t_to_ns
    start = t_from_ns if t_from_ns is not None else first_time(reader, things, None)
    if start is None:  # nothing recorded: the range stays empty either way
        return t_from_ns, t_to_ns
    return start + offset_ns, t_to_ns


def _rows(reader: HistoryReader, thing: str, t_from_ns: int | None, t_to_ns: int | None,
          names: list[str] | None, page: int) -> Iterator[Row]:
    for rows in reader.pages(thing, t_from_ns, t_to_ns, names, page):
        for seq, t, kind, name, data in rows:
            yield thing, seq, t, kind, name, data


def merged_pages(reader: HistoryReader, things: Sequence[str], t_from_ns: int | None = None,
                 t_to_ns: int | None = None, names: list[str] | None = None,
                 page: int = 20_000) -> Iterator[list[Row]]:
    """Pages of ``Row`` of every Thing in ``things``, in time order (one Thing: its pages as read)."""
    if len(things) == 1:
        thing = things[0]
        for rows in reader.pages(thing, t_from_ns, t_to_ns, names, page):
            yield [(thing, seq, t, kind, name, data) for seq, t, kind, name, data in rows]
        return
    streams = [_rows(reader, th, t_from_ns, t_to_ns, names, page) for th in things]
    out: list[Row] = []
    for row in heapq.merge(*streams, key=lambda r: r[2]):
        out.append(row)
        if len(out) >= page:
            yield out
            out = []
    if out:
        yield out
