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
into the freed ones and truncates the file (at the WAL checkpoint right after): the file
shrinks to ``retention_mb`` (the free pages within it are left for the next inserts; without
a size limit, to what the data uses), and a hub over ``retention_mb`` keeps its file at
about the limit while it keeps writing. The cost is proportional to
what was freed (pages moved), paid in the writer thread once per check. A file still
without auto-vacuum (``PRAGMA auto_vacuum`` 0) reuses its freed pages instead: it stops
growing at about the limit, without shrinking. PostgreSQL: autovacuum makes the space of
deleted rows reusable; the table does not shrink (``VACUUM FULL`` does, offline).

When a pass runs (``RetentionClock``, asked by the writer's thread between batches): every
``check_every_s``, and with ``max_mb`` also as soon as the database has grown by ``GROWTH_SHARE``
of it (at least ``GROWTH_MIN_BYTES``) since the last pass, at most one pass per
``MIN_GAP_S``: with raw images recorded a minute can write many times the budget (issue 48: 797 MB
for ``retention_mb = 30`` at 30 images/s). Growth is what the files take on disk (SQLite: the
database and its WAL, a ``stat`` each; PostgreSQL: ``pg_total_relation_size('events')``, asked at
most every ``PG_SIZE_EVERY_S``). After a pass that deleted, SQLite's WAL is checkpointed with
``TRUNCATE`` (waiting ``CHECKPOINT_WAIT_MS`` at most for readers, never the connection's 10 s), so the
file pair stays near the budget rather than the WAL keeping the size it grew to.
"""

from __future__ import annotations

import logging
import math
import os
import time
from dataclasses import dataclass
from typing import Any

import sqlalchemy as sa
from sqlalchemy.engine import Connection, Engine

from wott_hub.errors import InvalidInput

from .models import AuditRow, EventRow, ThingRow

__all__ = ["AUDIT_MAX_ROWS", "AUDIT_SHARE", "Retention", "RetentionClock", "apply_retention", "give_back",
           "trim_audit", "used_bytes"]

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


GROWTH_SHARE = 0.1
"""A pass runs once the database has grown by this share of ``max_mb`` since the last one..."""
GROWTH_MIN_BYTES = 1 << 20
"""...or by this many bytes, whichever is more."""
MIN_GAP_S = 1.0
"""Passes triggered by growth are at least this far apart (each costs a few queries)."""
PG_SIZE_EVERY_S = 5.0
"""PostgreSQL's table size is asked at most this often (a query, where SQLite's is a ``stat``)."""
CHECKPOINT_WAIT_MS = 200
"""The ``TRUNCATE`` checkpoint waits at most this long for readers, then is left for the next pass."""


class RetentionClock:
    """When the writer's thread runs the next retention pass: ``due()`` between batches, ``done()``
    after the pass. Time alone (every ``check_every_s``) lets a fast writer put many times
    ``max_mb`` on disk between two passes; the bytes the database grew by say when to run sooner."""

    def __init__(self, retention: Retention, engine: Engine) -> None:
        self.retention = retention
        self.engine = engine
        self._next = 0.0  # the first pass at once (the audit trail's bound, a database over its limit)
        self._last = -1e9
        self._after = 0  # the size right after the last pass
        self._step = max(GROWTH_MIN_BYTES, int(GROWTH_SHARE * (retention.max_mb or 0) * 1e6))
        url = engine.url
        name = url.database or ""
        self._files: tuple[str, ...] | None = None
        if engine.dialect.name == "sqlite" and name and name != ":memory:" and not name.startswith("file:"):
            self._files = (name, name + "-wal")
        self._pg = engine.dialect.name == "postgresql"
        self._size_at = -1e9

    def due(self) -> bool:
        now = time.monotonic()
        if now >= self._next:
            return True
        if not self.retention.max_mb or now - self._last < MIN_GAP_S:
            return False
        size = self._size(now)
        return size is not None and size - self._after >= self._step

    def done(self) -> None:
        now = time.monotonic()
        self._last = now
        self._next = now + self.retention.check_every_s
        self._size_at = -1e9  # measured again now, whatever the throttle
        self._after = self._size(now) or 0

    def _size(self, now: float) -> int | None:
        """The database's bytes on disk (None: not known, or not asked again yet)."""
        if self._files is not None:
            total = 0
            for f in self._files:
                try:
                    total += os.stat(f).st_size
                except OSError:
                    pass
            return total
        if not self._pg or now - self._size_at < PG_SIZE_EVERY_S:
            return None
        self._size_at = now
        try:
            with self.engine.connect() as conn:
                return int(conn.exec_driver_sql("SELECT pg_total_relation_size('events')").scalar_one())
        except Exception:  # the database is away: the batches say so; the clock waits for its time
            return None


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
    if conn.dialect.name == "sqlite":
        # Debian's SQLite zeroes every freed page (SECURE_DELETE): deleting a minute of raw images
        # would write as much again through the WAL. FAST zeroes what is in pages written anyway
        # (the rows' B-tree pages), not freed overflow pages (images), which the next inserts or
        # the vacuum right after reuse or cut off (issue 48)
        conn.exec_driver_sql("PRAGMA secure_delete=FAST")
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
        give_back(engine, keep_bytes=int(r.max_mb * 1e6) if r.max_mb else None)
    return deleted


def give_back(engine: Engine, keep_bytes: int | None = None) -> int:
    """SQLite: return the free pages to the file system (with incremental auto-vacuum) and
    truncate the WAL; returns how many pages were free. Elsewhere nothing to do (0).

    ``keep_bytes``: the file is shrunk to this size, not below: the free pages within it are left
    for the next inserts (a hub that keeps writing would fill them within seconds; moving the
    last pages into them would write them all again, through the WAL)."""
    if engine.dialect.name != "sqlite":
        return 0
    with engine.connect() as conn:
        raw: Any = conn.connection.driver_connection
        wait = conn.exec_driver_sql("PRAGMA busy_timeout").scalar()
        # the WAL back to 0 bytes (the file shrinks at a checkpoint): a reader that holds it makes
        # this wait CHECKPOINT_WAIT_MS at most, then it is left for the next pass. Before the vacuum
        # too: the pages it moves go through the WAL, which then holds only them
        truncate = (f"PRAGMA busy_timeout={CHECKPOINT_WAIT_MS}; PRAGMA wal_checkpoint(TRUNCATE); "
                    f"PRAGMA busy_timeout={int(wait or 0)};")
        raw.executescript(truncate)
        free = 0
        if conn.exec_driver_sql("PRAGMA auto_vacuum").scalar() == 2:
            free = conn.exec_driver_sql("PRAGMA freelist_count").scalar() or 0
            n = free
            if keep_bytes is not None and free:
                pages = conn.exec_driver_sql("PRAGMA page_count").scalar() or 0
                page = conn.exec_driver_sql("PRAGMA page_size").scalar() or 1
                n = min(free, max(0, pages - keep_bytes // page))
            if n:
                # one page per step, and sqlite3's execute steps once: executescript runs it to its end
                raw.executescript(f"PRAGMA incremental_vacuum({int(n)});")
                raw.executescript(truncate)
    return int(free)
