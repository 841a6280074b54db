"""One writer per hub identity in a history database: the ``hub_lease`` rows.

Two processes writing as the same hub interleave their sequence numbers into the
same Things (and then collide on (thing, seq)). So the writer takes its hub's lease
before it records anything and refuses with ``wott_hub.errors.Conflict``,
naming the database and the holder, while another process holds it. Hubs of
*different* ids (a fleet sharing one PostgreSQL database, issue 13) each hold
their own row and write side by side: their Things are distinct.

Contract:
- The row is the one of ``hub_id`` (``DEFAULT_HUB_ID`` for a hub configured
  without one: migration 0005 creates it; another id's row is inserted on first
  use, ``ON CONFLICT DO NOTHING``).
- Taking, refreshing and releasing are each one conditional UPDATE of that row
  (``WHERE holder IS NULL OR holder = me OR heartbeat older than stale_s``):
  SQLite serialises writers, PostgreSQL re-checks the WHERE after a row lock,
  so of two processes racing, exactly one gets the row on either engine.
- The holder is this *process* (host, pid, a random tag): several writers of
  one process (a hub restarted in-process, tests) share it, two processes never.
- A lease whose heartbeat is older than ``stale_s`` may be taken over (the
  holder hung or its host died); one held by a process of this host that no
  longer exists (SIGKILL, crash) is taken over at once.
- A Thing is recorded by one hub id (``things.hub_id``): another hub id registering it is
  refused (``Conflict``) while the recording hub's holder is live (``live_holder``), and
  takes it over otherwise (a hub renamed, or gone for good).
- A writer that finds its lease taken over stops writing (see writer.py):
  a paused hub must not interleave with the one that took its place.
- Kept by its holder's writer thread: ``keep`` refreshes the heartbeat every ``stale_s / 6`` s
  (``next_refresh``), so a holder must stall for five refreshes in a row to lose it.
"""

from __future__ import annotations

import importlib
import os
import socket
import time
import uuid
from dataclasses import dataclass

import sqlalchemy as sa
from sqlalchemy.engine import Engine

from wott_hub.errors import Conflict, InvalidInput

from .db import describe
from .db_errors import translated
from .models import HubLeaseRow

__all__ = ["DEFAULT_HUB_ID", "LEASE_STALE_S", "Lease", "LeaseHolder", "check_hub_id", "live_holder",
           "this_process"]

DEFAULT_HUB_ID = "wott-hub"
"""The hub id of a hub that is not told its own (a single hub per database); migration 0005
creates its row. A fleet gives each hub its identity (``HistoryWriter(..., hub_id=...)``)."""

LEASE_STALE_S = 30.0
"""A holder that has not refreshed for this long is presumed dead (the writer refreshes every
``stale_s / 6`` s, so a holder must stall for five refreshes in a row to lose it)."""

_T = HubLeaseRow.__table__


@dataclass(frozen=True)
class LeaseHolder:
    holder: str
    pid: int
    host: str
    heartbeat_ns: int

    def __str__(self) -> str:
        age = max(0.0, (time.time_ns() - self.heartbeat_ns) / 1e9)
        return f"process {self.pid} on {self.host} (last seen {age:.0f} s ago)"


_ME = f"{socket.gethostname()[:60]}:{os.getpid()}:{uuid.uuid4().hex[:12]}"
_ME_PID = os.getpid()


def this_process() -> str:
    """The holder id of this process (a fork gets its own)."""
    global _ME, _ME_PID
    if os.getpid() != _ME_PID:
        _ME, _ME_PID = f"{socket.gethostname()[:60]}:{os.getpid()}:{uuid.uuid4().hex[:12]}", os.getpid()
    return _ME


def _alive_here(holder: LeaseHolder) -> bool:
    """Could the holder still be running? False only when it is provably gone (this host, no pid)."""
    if holder.host != socket.gethostname():
        return True
    try:
        os.kill(holder.pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, another user's
        return True
    return True


def check_hub_id(hub_id: object) -> str:
    """``hub_id`` if it can key a lease row (1-200 characters of text), else InvalidInput."""
    if not isinstance(hub_id, str) or not hub_id.strip() or len(hub_id) > 200:
        raise InvalidInput(f"the history hub id must be a non-empty string of at most 200 "
                           f"characters, got {hub_id!r}")
    return hub_id


def live_holder(conn: sa.Connection, hub_id: str, stale_s: float = LEASE_STALE_S) -> LeaseHolder | None:
    """The process holding ``hub_id``'s lease if it may still be writing (fresh heartbeat, not
    provably gone), else None."""
    row = conn.execute(sa.select(_T.c.holder, _T.c.pid, _T.c.host, _T.c.heartbeat_ns)
                       .where(_T.c.hub_id == hub_id)).first()
    if row is None or row[0] is None:
        return None
    holder = LeaseHolder(row[0], row[1] or 0, row[2] or "?", row[3] or 0)
    if holder.heartbeat_ns < time.time_ns() - int(stale_s * 1e9) or not _alive_here(holder):
        return None
    return holder


class Lease:
    def __init__(self, engine: Engine, *, hub_id: str = DEFAULT_HUB_ID,
                 stale_s: float = LEASE_STALE_S) -> None:
        self.engine = engine
        self.hub_id = check_hub_id(hub_id)
        self.stale_s = stale_s
        self.held = False
        self.lost = ""  # why the lease was lost (someone took it over), else ""
        self.next_refresh = 0.0  # time.monotonic() when ``keep`` refreshes the heartbeat next

    @property
    def me(self) -> str:
        return this_process()

    @property
    def _mine(self) -> sa.ColumnElement[bool]:
        return _T.c.hub_id == self.hub_id

    def _insert_row(self, conn: sa.Connection) -> None:
        """Create this hub id's row unless a racing writer just did (then its UPDATE decides)."""
        name = conn.dialect.name
        if name in ("sqlite", "postgresql"):
            dialect = importlib.import_module(f"sqlalchemy.dialects.{name}")
            conn.execute(dialect.insert(_T).values(hub_id=self.hub_id)
                         .on_conflict_do_nothing(index_elements=[_T.c.hub_id]))
        else:  # other engines: a plain insert (a lost race is an IntegrityError, reported as such)
            conn.execute(_T.insert().values(hub_id=self.hub_id))

    def holder(self) -> LeaseHolder | None:
        with translated(), self.engine.connect() as conn:
            row = conn.execute(sa.select(_T.c.holder, _T.c.pid, _T.c.host, _T.c.heartbeat_ns)
                               .where(self._mine)).first()
        if row is None or row[0] is None:
            return None
        return LeaseHolder(row[0], row[1] or 0, row[2] or "?", row[3] or 0)

    def _take(self, conn: sa.Connection, *, also_holder: str | None = None) -> bool:
        now = time.time_ns()
        cond = sa.or_(_T.c.holder.is_(None), _T.c.holder == self.me,
                      _T.c.heartbeat_ns < now - int(self.stale_s * 1e9))
        if also_holder is not None:
            cond = sa.or_(cond, _T.c.holder == also_holder)
        res = conn.execute(_T.update().where(self._mine, cond).values(
            holder=self.me, pid=os.getpid(), host=socket.gethostname()[:255], heartbeat_ns=now,
            acquired_ns=sa.case((_T.c.holder == self.me, _T.c.acquired_ns), else_=now)))
        return bool(res.rowcount == 1)

    def acquire(self) -> None:
        """Take the lease or raise Conflict naming the database and the holder."""
        where = describe(self.engine.url)
        with translated(f"cannot take the writer lease of the history database {where!r}"):
            with self.engine.begin() as conn:  # write first: SQLite takes its write lock at once
                taken = self._take(conn)
                if not taken and conn.execute(sa.select(_T.c.id).where(self._mine)).first() is None:
                    self._insert_row(conn)  # this hub id's first writer (or a hand-migrated database)
                    taken = self._take(conn)
            if taken:
                self._taken()
                return
            other = self.holder()
            if other is not None and not _alive_here(other):
                with self.engine.begin() as conn:
                    if self._take(conn, also_holder=other.holder):
                        self._taken()
                        return
                other = self.holder()
        who = str(other) if other is not None else "another process"
        same = "" if self.hub_id == DEFAULT_HUB_ID else f" with the same hub id {self.hub_id!r}"
        raise Conflict(f"the history database {describe(self.engine.url)!r} is in use by another hub{same}: "
                       f"{who}; stop it first, or give this hub another database or hub id")

    def _taken(self) -> None:
        self.held, self.lost = True, ""
        self.next_refresh = time.monotonic() + self.stale_s / 6

    def keep(self) -> bool:
        """Refresh the heartbeat if it is due (every ``stale_s / 6`` s while held); False only when
        this refresh found the lease taken over (``lost`` says by whom)."""
        if not self.held or time.monotonic() < self.next_refresh:
            return True
        self.next_refresh = time.monotonic() + self.stale_s / 6
        return self.refresh()

    def refresh(self) -> bool:
        """Move the heartbeat; False (and ``lost`` says why) if another process took the lease."""
        if not self.held:
            return False
        with translated(), self.engine.begin() as conn:
            res = conn.execute(_T.update().where(self._mine, _T.c.holder == self.me)
                               .values(heartbeat_ns=time.time_ns()))
            if res.rowcount == 1:
                return True
            if self._take(conn):  # released by a writer of this same process meanwhile
                return True
        other = self.holder()
        self.held = False
        self.lost = (f"the writer lease of {describe(self.engine.url)!r} was taken over by "
                     f"{other or 'another process'}: this hub stopped recording")
        return False

    def release(self) -> None:
        if not self.held:
            return
        self.held = False
        with translated(), self.engine.begin() as conn:
            conn.execute(_T.update().where(self._mine, _T.c.holder == self.me)
                         .values(holder=None, pid=None, host=None, heartbeat_ns=None, acquired_ns=None))
