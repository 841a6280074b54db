"""The audit trail: every write, action and refused credential, kept in the history database.

``AuditLog.record`` is called from the event loop (the gate's output transform, once
per audited request) and only appends to a bounded queue; a daemon thread inserts the
entries into ``audit_log`` (Alembic revision 0004) in batches, so a database that is
slow never slows a request. Before the database is attached (the hub opens it a
moment after serving) or without history, entries wait in memory (at most
``MAX_WAITING``, oldest dropped) and are logged either way: refusals at WARNING,
writes and actions at INFO. Nothing recorded or logged holds a secret: ``who`` is a
token's name and ``target`` a path without its query.
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from dataclasses import asdict, dataclass
from typing import Any

__all__ = ["AuditEntry", "AuditLog", "read_audit"]

log = logging.getLogger("wott_hub.audit")
MAX_WAITING = 10_000


@dataclass(frozen=True)
class AuditEntry:
    t_ns: int
    who: str
    action: str
    target: str
    address: str
    status: int


class AuditLog:
    def __init__(self) -> None:
        self._waiting: collections.deque[AuditEntry] = collections.deque(maxlen=MAX_WAITING)
        self._cond = threading.Condition()
        self._engine: Any = None
        self._thread: threading.Thread | None = None
        self._stopping = False

    def record(self, who: str, action: str, target: str, address: str, status: int) -> None:
        entry = AuditEntry(time.time_ns(), who[:64], action[:16], target, address[:64], status)
        if status in (401, 403):
            log.warning("refused %s %s from %s (%s): %d", action, target, address, who, status)
        else:
            log.info("%s %s by %s from %s: %d", action, target, who, address, status)
        with self._cond:
            self._waiting.append(entry)
            self._cond.notify()

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

    def _run(self) -> None:
        from wott_hub.history.models import AuditRow

        table = AuditRow.__table__
        while True:
            with self._cond:
                while not self._waiting and not self._stopping:
                    self._cond.wait(1.0)
                batch = list(self._waiting)
                self._waiting.clear()
                stopping = self._stopping
            if batch:
                try:
                    with self._engine.begin() as conn:
                        conn.execute(table.insert(), [asdict(e) for e in batch])
                except Exception:  # an audit write that fails must not take the hub down
                    log.exception("could not write %d audit entries", len(batch))
            if stopping:
                return

    def pending(self) -> list[AuditEntry]:
        with self._cond:
            return list(self._waiting)


def read_audit(engine: Any, *, limit: int = 100, who: str | None = None,
               since_ns: int | None = None) -> list[AuditEntry]:
    """The newest ``limit`` entries, oldest first (``wott-hub history audit``)."""
    import sqlalchemy as sa

    from wott_hub.history.models import AuditRow

    t = AuditRow.__table__
    q = sa.select(t.c.t_ns, t.c.who, t.c.action, t.c.target, t.c.address, t.c.status)
    if who is not None:
        q = q.where(t.c.who == who)
    if since_ns is not None:
        q = q.where(t.c.t_ns >= since_ns)
    q = q.order_by(t.c.id.desc()).limit(limit)
    with engine.connect() as conn:
        rows = conn.execute(q).all()
    return [AuditEntry(*r) for r in reversed(rows)]
