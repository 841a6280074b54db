"""Retention: drop the oldest events by age and/or by database size.

Runs in the writer thread (no lock contention with the batches). Age is exact.
Size is the space the data uses (SQLite: pages in use; PostgreSQL: the bytes of
the live rows of events, scaled by the table's index-to-heap ratio: deleted rows
keep their space until autovacuum makes it reusable, as SQLite's free pages are,
so the table's size on disk does not say what is used); when over the limit, events older than a cut-off
time are deleted, the cut-off chosen from the time span the data covers so
that about 90 % of the limit remains, repeated until under it.

The audit trail (``audit_log``, ``security/audit.py``) is trimmed in the same pass, and
always, retention configured or not: by age like events (``days``), to at most
``AUDIT_MAX_ROWS`` rows, and to ``AUDIT_SHARE`` of ``max_mb``. It is trimmed first, so that what
it uses never makes the size pass delete devices' events (requests anyone can send must not
erase history: issue 33).

Giving the space back: an SQLite history database is made with ``auto_vacuum =
INCREMENTAL`` (``db.py``; migration 0006 converts an older file with one ``VACUUM``),
so after a pass that deleted rows ``PRAGMA incremental_vacuum`` moves the last pages
into the freed ones and truncates the file (at the next WAL checkpoint, run passively
right after): the file shrinks to what the data uses, and a hub over ``retention_mb``
keeps its file at about the limit while it keeps writing. The cost is proportional to
what was freed (pages moved), paid in the writer thread once per check. A file still
without auto-vacuum (``PRAGMA auto_vacuum`` 0) reuses its freed pages instead: it stops
growing at about the limit, without shrinking. PostgreSQL: autovacuum makes the space of
deleted rows reusable; the table does not shrink (``VACUUM FULL`` does, offline).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass
from typing import Any

import sqlalchemy as sa
from sqlalchemy.engine import Connection, Engine

from wott_hub.errors import InvalidInput

from .models import AuditRow, EventRow, ThingRow

__all__ = ["AUDIT_MAX_ROWS", "AUDIT_SHARE", "Retention", "apply_retention", "give_back", "trim_audit",
           "used_bytes"]

log = logging.getLogger(__name__)

AUDIT_MAX_ROWS = 100_000
"""Audit rows kept at most (~35 MB with paths at their 256-character cut), retention or not."""
AUDIT_SHARE = 0.05
"""The part of ``retention_mb`` the audit trail may use."""
_AUDIT_ROW_BYTES = 120
"""What an audit row costs beside its target's text (columns, row header, the t_ns index entry)."""


@dataclass(frozen=True)
class Retention:
    days: float | None = None
    max_mb: float | None = None
    check_every_s: float = 60.0

    def __post_init__(self) -> None:
        # checked here too (not only at config load): an infinite age would fail every minute
        for name, top in (("days", 36_500.0), ("max_mb", 1e9), ("check_every_s", 86_400.0)):
            v = getattr(self, name)
            ok = isinstance(v, int | float) and math.isfinite(v) and 0 <= v <= top
            if v is not None and not (ok and (v > 0 or name != "check_every_s")):  # days/max_mb 0: off
                raise InvalidInput(f"retention {name} must be a number in (0, {top:g}], got {v!r}")

    @property
    def active(self) -> bool:
        return bool(self.days) or bool(self.max_mb)


def used_bytes(conn: Connection) -> int | None:
    name = conn.dialect.name
    if name == "sqlite":
        pages = conn.exec_driver_sql("PRAGMA page_count").scalar_one()  # each PRAGMA answers one row
        free = conn.exec_driver_sql("PRAGMA freelist_count").scalar_one()
        size = conn.exec_driver_sql("PRAGMA page_size").scalar_one()
        return int((pages - free) * size)
    if name == "postgresql":  # a scan of events: retention runs once a minute, off the hot path
        live, heap, total = conn.exec_driver_sql(
            "SELECT (SELECT coalesce(sum(pg_column_size(e.*) + 28), 0) FROM events e), "  # + header
            "pg_relation_size('events'), pg_total_relation_size('events')").one()
        return int(live * total / heap) if heap else int(live)
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
    lo: int | None = None
    hi: int | None = None
    for key in keys:
        a, b = conn.execute(sa.select(sa.func.min(events.c.t_ns), sa.func.max(events.c.t_ns))
                            .where(events.c.thing_key == key)).one()
        if a is None:
            continue
        lo = a if lo is None else min(lo, a)
        hi = b if hi is None else max(hi, b)
    return None if lo is None or hi is None else (lo, hi)  # both set together


def trim_audit(engine: Engine, r: Retention, now_ns: int | None = None) -> int:
    """Delete audit rows older than ``r.days`` and the oldest beyond the audit's budget (rows and
    bytes); returns how many went."""
    audit = AuditRow.__table__
    now_ns = now_ns if now_ns is not None else time.time_ns()
    deleted = 0
    if r.days:
        with engine.begin() as conn:
            deleted += conn.execute(audit.delete().where(
                audit.c.t_ns < now_ns - int(r.days * 86400e9))).rowcount or 0
    with engine.connect() as conn:
        rows, text = conn.execute(sa.select(sa.func.count(), sa.func.coalesce(
            sa.func.sum(sa.func.length(audit.c.target)), 0))).one()
    keep = AUDIT_MAX_ROWS
    if r.max_mb and rows:
        per_row = _AUDIT_ROW_BYTES + text / rows
        keep = min(keep, int(AUDIT_SHARE * r.max_mb * 1e6 / per_row))
    if rows > keep:
        with engine.begin() as conn:
            last = conn.execute(sa.select(audit.c.id).order_by(audit.c.id.desc())
                                .offset(keep).limit(1)).scalar()
            if last is not None:
                deleted += conn.execute(audit.delete().where(audit.c.id <= last)).rowcount or 0
    return deleted


def apply_retention(engine: Engine, r: Retention, now_ns: int | None = None) -> int:
    """Delete what the policy says is too old or too much; returns the number of events deleted.
    The audit trail is trimmed first (``trim_audit``), retention configured or not."""
    now_ns = now_ns if now_ns is not None else time.time_ns()
    trimmed = trim_audit(engine, r, now_ns)
    if not r.active:
        if trimmed:
            give_back(engine)
        return 0
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
            if span is None or used is None or span[0] >= span[1]:  # used is set when span is
                break
            lo, hi = span
            keep = max(0.0, min(1.0, 0.9 * limit / used))
            with engine.begin() as conn:
                n = _delete_before(conn, keys, int(hi - (hi - lo) * keep))
            deleted += n
            if n == 0:
                break
    if deleted or trimmed:
        log.info("retention deleted %d events and %d audit rows", deleted, trimmed)
        give_back(engine)
    return deleted


def give_back(engine: Engine) -> int:
    """SQLite with incremental auto-vacuum: return the free pages to the file system; returns
    how many pages were free. Elsewhere nothing to do (0)."""
    if engine.dialect.name != "sqlite":
        return 0
    with engine.connect() as conn:
        if conn.exec_driver_sql("PRAGMA auto_vacuum").scalar() != 2:
            return 0
        free = conn.exec_driver_sql("PRAGMA freelist_count").scalar() or 0
        if free:
            raw: Any = conn.connection.driver_connection
            # one page per step, and sqlite3's execute steps once: executescript runs it to its end
            raw.executescript("PRAGMA incremental_vacuum; PRAGMA wal_checkpoint(PASSIVE);")
    return int(free)
