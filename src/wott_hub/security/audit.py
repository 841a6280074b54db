"""The audit trail: every write, action and refused credential, kept in the history database.

``AuditLog.record`` is called from the event loop (the gate's output transform, once
per audited request) and only touches memory; a daemon thread writes the entries into
``audit_log`` (Alembic revisions 0004, 0007) about once a second, so a database that is
slow never slows a request. Before the database is attached (the hub opens it a
moment after serving) or without history, entries wait in memory. Nothing recorded or
logged holds a secret: ``who`` is a token's name and ``target`` a path without its query.

Bounded, whatever clients send (an unauthenticated flood must not grow the database or the
log without end, nor push the devices' history out through retention):
- ``target`` is cut to ``MAX_TARGET`` characters (a 60,000-character path is stored as its
  first 256 and ``…``);
- identical entries (who, action, target, address, status) are one row with a ``count`` and
  the time of the last (``last_ns``): those of the same second are merged in memory, and a row
  written in the last ``MERGE_S`` takes later ones by an UPDATE;
- one address gets at most ``MAX_TARGETS_PER_MINUTE`` distinct refused targets a minute;
  beyond them its refusals are counted in one row whose target is ``OTHER_TARGETS``;
- at most ``MAX_WAITING`` distinct entries wait in memory (the oldest dropped, counted);
- the table is trimmed by the history writer's retention (``history/retention.py``: by age
  like events, to ``MAX_ROWS`` rows, and to its share of ``retention_mb``);
- refusals are logged at WARNING at most ``LOG_BURST`` a minute (``LogRate``), then one line
  says how many were not; writes and actions at INFO, with the same cut of the path.
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from dataclasses import asdict, dataclass
from typing import Any

from .lograte import LogRate

__all__ = ["MAX_TARGET", "MERGE_S", "OTHER_TARGETS", "AuditEntry", "AuditLog", "clip", "read_audit"]

log = logging.getLogger("wott_hub.audit")
MAX_WAITING = 10_000
MAX_TARGET = 256
MERGE_S = 60.0
MAX_TARGETS_PER_MINUTE = 60
OTHER_TARGETS = "(other paths)"
LOG_BURST = 20
_REFUSED = (401, 403)

Key = tuple[str, str, str, str, int]  # who, action, target, address, status


def clip(text: str, limit: int = MAX_TARGET) -> str:
    """``text`` cut to ``limit`` characters, ``…`` saying it was."""
    return text if len(text) <= limit else text[:limit - 1] + "…"


@dataclass(frozen=True)
class AuditEntry:
    t_ns: int
    who: str
    action: str
    target: str
    address: str
    status: int
    count: int = 1
    """How many identical requests this entry stands for (the first at ``t_ns``, the last at ``last_ns``)."""
    last_ns: int | None = None


class AuditLog:
    def __init__(self) -> None:
        self._waiting: dict[Key, AuditEntry] = {}  # insertion order: oldest first
        self._cond = threading.Condition()
        self._engine: Any = None
        self._thread: threading.Thread | None = None
        self._stopping = False
        self._rows: collections.OrderedDict[Key, tuple[int, float]] = collections.OrderedDict()
        """Rows written in the last ``MERGE_S``: key -> (row id, time.monotonic() written)."""
        self._targets: dict[str, tuple[int, set[str]]] = {}  # address -> (minute, refused targets)
        self.dropped = 0
        self.log_rate = LogRate(log, LOG_BURST, 60.0, "refused requests")

    def record(self, who: str, action: str, target: str, address: str, status: int) -> None:
        now = time.time_ns()
        who, action, target, address = who[:64], action[:16], clip(target), address[:64]
        if status in _REFUSED:
            target = self._refused_target(address, target, now)
            if self.log_rate.allow():
                log.warning("refused %s %s from %s (%s): %d", action, target, address, who, status)
        else:
            log.info("%s %s by %s from %s: %d", action, target, who, address, status)
        key = (who, action, target, address, status)
        with self._cond:
            seen = self._waiting.get(key)
            if seen is not None:
                self._waiting[key] = AuditEntry(seen.t_ns, who, action, target, address, status,
                                                seen.count + 1, now)
                return
            if len(self._waiting) >= MAX_WAITING:
                oldest = next(iter(self._waiting))
                self.dropped += self._waiting.pop(oldest).count
            self._waiting[key] = AuditEntry(now, who, action, target, address, status)
            self._cond.notify()

    def _refused_target(self, address: str, target: str, now_ns: int) -> str:
        """``target``, or ``OTHER_TARGETS`` once ``address`` had its share of distinct ones this minute."""
        minute = now_ns // 60_000_000_000
        seen = self._targets.get(address)
        if seen is None or seen[0] != minute:
            if len(self._targets) > 4 * MAX_WAITING:  # many addresses: forget the past minutes
                self._targets = {a: v for a, v in self._targets.items() if v[0] == minute}
            seen = self._targets[address] = (minute, set())
        targets = seen[1]
        if target in targets:
            return target
        if len(targets) >= MAX_TARGETS_PER_MINUTE:
            return OTHER_TARGETS
        targets.add(target)
        return target

    def attach(self, engine: Any) -> None:
        """Start writing into ``engine``'s ``audit_log`` (what waited first)."""
        if engine is None or self._thread is not None:
            return
        self._engine = engine
        self._stopping = False
        self._thread = threading.Thread(target=self._run, name="audit-writer", daemon=True)
        self._thread.start()

    def close(self, timeout: float = 5.0) -> None:
        """Write what is queued, then stop (before the engine is disposed)."""
        if self._thread is None:
            return
        with self._cond:
            self._stopping = True
            self._cond.notify()
        self._thread.join(timeout)
        self._thread = None
        self._engine = None
        self.log_rate.flush()

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._waiting and not self._stopping:
                    self._cond.wait(1.0)
                until = time.monotonic() + 1.0  # a second to merge what comes in the meantime
                while not self._stopping and (left := until - time.monotonic()) > 0:
                    self._cond.wait(left)
                batch = list(self._waiting.values())
                self._waiting.clear()
                stopping = self._stopping
            self.log_rate.flush()
            if batch:
                try:
                    self._write(batch)
                except Exception:  # an audit write that fails must not take the hub down
                    log.exception("could not write %d audit entries", len(batch))
            if stopping:
                return

    def _write(self, batch: list[AuditEntry]) -> None:
        from wott_hub.history.models import AuditRow

        table = AuditRow.__table__
        now = time.monotonic()
        rows = self._rows
        while rows and (next(iter(rows.values()))[1] < now - MERGE_S or len(rows) > 5 * MAX_WAITING):
            rows.popitem(last=False)
        merge: list[AuditEntry] = []
        new: list[AuditEntry] = []
        for e in batch:
            key = (e.who, e.action, e.target, e.address, e.status)
            (merge if key in rows else new).append(e)
        with self._engine.begin() as conn:
            for e in merge:
                row_id = rows[(e.who, e.action, e.target, e.address, e.status)][0]
                conn.execute(table.update().where(table.c.id == row_id).values(
                    count=table.c.count + e.count, last_ns=e.last_ns or e.t_ns))
            if new:
                ids = conn.execute(table.insert().returning(table.c.id, sort_by_parameter_order=True),
                                   [asdict(e) for e in new]).scalars().all()
                for e, row_id in zip(new, ids, strict=True):
                    rows[(e.who, e.action, e.target, e.address, e.status)] = (row_id, now)

    def pending(self) -> list[AuditEntry]:
        with self._cond:
            return list(self._waiting.values())


def read_audit(engine: Any, *, limit: int = 100, who: str | None = None,
               since_ns: int | None = None) -> list[AuditEntry]:
    """The newest ``limit`` entries, oldest first (``wott-hub history audit``)."""
    import sqlalchemy as sa

    from wott_hub.history.models import AuditRow

    t = AuditRow.__table__
    q = sa.select(t.c.t_ns, t.c.who, t.c.action, t.c.target, t.c.address, t.c.status, t.c.count, t.c.last_ns)
    if who is not None:
        q = q.where(t.c.who == who)
    if since_ns is not None:
        q = q.where(t.c.t_ns >= since_ns)
    q = q.order_by(t.c.id.desc()).limit(limit)
    with engine.connect() as conn:
        rows = conn.execute(q).all()
    return [AuditEntry(*r) for r in reversed(rows)]
