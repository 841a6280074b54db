"""Retention: drop the oldest events by age and/or by database size.

Runs in the writer thread (no lock contention with the batches). Age is exact.
Size is the space the data uses (SQLite: pages in use; PostgreSQL: the events
table with its indexes); when over the limit, events older than a cut-off
time are deleted, the cut-off chosen from the time span the data covers so
that about 90 % of the limit remains, repeated until under it. An SQLite file
does not shrink when rows are deleted: the freed pages are reused, so the file
stops growing at about the limit (``VACUUM`` gives the space back to the OS).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import sqlalchemy as sa
from sqlalchemy.engine import Connection, Engine

from .models import EventRow, ThingRow

__all__ = ["Retention", "apply_retention", "used_bytes"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Retention:
    days: float | None = None
    max_mb: float | None = None
    check_every_s: float = 60.0

    @property
    def active(self) -> bool:
        return bool(self.days) or bool(self.max_mb)


def used_bytes(conn: Connection) -> int | None:
    name = conn.dialect.name
    if name == "sqlite":
        pages = conn.exec_driver_sql("PRAGMA page_count").scalar()
        free = conn.exec_driver_sql("PRAGMA freelist_count").scalar()
        size = conn.exec_driver_sql("PRAGMA page_size").scalar()
        return (pages - free) * size
    if name == "postgresql":
        return conn.exec_driver_sql("SELECT pg_total_relation_size('events')").scalar()
    return None


def _delete_before(conn: Connection, keys: list[int], cutoff_ns: int) -> int:
    events = EventRow.__table__
    n = 0
    for key in keys:  # per Thing: each delete is a range of the (thing_key, t_ns) index
        n += conn.execute(events.delete().where(events.c.thing_key == key)
                          .where(events.c.t_ns < cutoff_ns)).rowcount or 0
    return n


def _span(conn: Connection, keys: list[int]) -> tuple[int, int] | None:
    events = EventRow.__table__
    lo, hi = None, None
    for key in keys:
        a, b = conn.execute(sa.select(sa.func.min(events.c.t_ns), sa.func.max(events.c.t_ns))
                            .where(events.c.thing_key == key)).one()
        if a is None:
            continue
        lo = a if lo is None else min(lo, a)
        hi = b if hi is None else max(hi, b)
    return None if lo is None else (lo, hi)


def apply_retention(engine: Engine, r: Retention, now_ns: int | None = None) -> int:
    """Delete what the policy says is too old or too much; returns the number of events deleted."""
    if not r.active:
        return 0
    now_ns = now_ns if now_ns is not None else time.time_ns()
    deleted = 0
    # reads and deletes in separate transactions: a transaction that reads first and then
    # writes can fail at once on SQLite (stale WAL snapshot) if another connection wrote meanwhile
    with engine.connect() as conn:
        keys = list(conn.execute(sa.select(ThingRow.__table__.c.key)).scalars())
    if r.days:
        with engine.begin() as conn:
            deleted += _delete_before(conn, keys, now_ns - int(r.days * 86400e9))
    if r.max_mb:
        limit = r.max_mb * 1e6
        for _ in range(8):
            with engine.connect() as conn:
                used = used_bytes(conn)
                span = _span(conn, keys) if used is not None and used > limit else None
            if span is None or span[0] >= span[1]:
                break
            lo, hi = span
            keep = max(0.0, min(1.0, 0.9 * limit / used))
            with engine.begin() as conn:
                n = _delete_before(conn, keys, int(hi - (hi - lo) * keep))
            deleted += n
            if n == 0:
                break
    if deleted:
        log.info("retention deleted %d events", deleted)
    return deleted
