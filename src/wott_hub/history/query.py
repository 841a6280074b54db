"""A page of one Thing's records for the hub's history API: a range, an affordance filter, a limit.

Paging is by sequence number (``after``): a client asks again with the last seq it got
until a page comes back shorter than its limit. The time range is turned into a seq range
once (``HistoryReader.seq_range``, through the time index); the name filter runs in SQL.
"""

from __future__ import annotations

import sqlalchemy as sa

from wott_hub.errors import NotFound

from .models import EventRow
from .reader import HistoryReader, decode_rows

__all__ = ["record_page"]

_E = EventRow.__table__


def record_page(reader: HistoryReader, thing: str, *, t_from_ns: int | None = None,
                t_to_ns: int | None = None, names: list[str] | None = None, after: int = 0,
                limit: int = 1000) -> list[tuple[int, int, int, str, str]]:
    """Up to ``limit`` (seq, t_ns, kind, name, data) of ``thing`` with seq > ``after``, in order."""
    key = reader.key(thing)
    if key is None:
        raise NotFound(f"no recorded device {thing!r}")
    bounds = reader.seq_range(thing, t_from_ns, t_to_ns)
    if bounds is None:
        return []
    lo, hi = bounds
    q = (sa.select(_E.c.seq, _E.c.t_ns, _E.c.kind, _E.c.name, _E.c.data)
         .where(_E.c.thing_key == key, _E.c.seq > max(after, lo - 1), _E.c.seq <= hi))
    if t_from_ns is not None:
        q = q.where(_E.c.t_ns >= t_from_ns)
    if t_to_ns is not None:
        q = q.where(_E.c.t_ns <= t_to_ns)
    if names:
        q = q.where(_E.c.name.in_(names))
    q = q.order_by(_E.c.seq).limit(limit)
    try:
        with reader.engine.connect() as conn:
            rows = conn.execute(q).all()
    except sa.exc.DBAPIError as e:
        raise reader._failed(e) from None
    return decode_rows(rows)
