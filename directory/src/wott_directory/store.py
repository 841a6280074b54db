"""The directory's storage: TDs in memory for reads and search, SQLAlchemy for durability.

``ThingStore``: persistence of TDs and events. Every write is one short transaction run on a
single dedicated thread, so the IOLoop (which the hub shares with its devices) never waits on
the database, and writes reach the database in the order the directory decided them.

``Catalogue``: every TD in a dict (id -> Enriched TD), loaded at start and changed only after
the database committed the change (``stored``, ``removed``), so reads never touch the database
and a failed write leaves both unchanged. It keeps what reads need beside it: the ids in order
(``page``), the array searches run on (``snapshot``, rebuilt after a change), each TD's size
(the store's byte budget), the marks (anonymous, the directory's own, held by the embedder,
too deep to search) and the collection's ``etag``.
"""

from __future__ import annotations

import asyncio
import bisect
import json
import secrets
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any, TypeVar

from sqlalchemy import create_engine, delete, event, insert, inspect, select, update
from sqlalchemy.engine import Engine
from sqlalchemy.pool import StaticPool

from .events import Event
from .models import EventRow, ThingRow, create_schema
from .registration import Enriched
from .validation import MAX_TD_DEPTH, json_depth

__all__ = ["Catalogue", "StoredThing", "ThingStore", "make_engine"]

T = TypeVar("T")


def make_engine(url: str) -> Engine:
    """An engine for ``url``; SQLite gets WAL and a shared connection for ``:memory:``."""
    if url.startswith("sqlite"):
        memory = url in ("sqlite://", "sqlite:///:memory:") or "mode=memory" in url
        kwargs: dict[str, Any] = {"connect_args": {"check_same_thread": False}}
        if memory:
            kwargs["poolclass"] = StaticPool
        engine = create_engine(url, **kwargs)
        if not memory:
            @event.listens_for(engine, "connect")
            def _pragmas(dbapi_conn: Any, _record: Any) -> None:
                cur = dbapi_conn.cursor()
                cur.execute("PRAGMA journal_mode=WAL")
                cur.execute("PRAGMA synchronous=NORMAL")
                cur.close()
        return engine
    for bare in ("postgresql://", "postgres://"):  # psycopg 3 is the driver installed with us
        if url.startswith(bare):
            url = "postgresql+psycopg://" + url.removeprefix(bare)
    return create_engine(url, pool_pre_ping=True)


@dataclass(frozen=True)
class StoredThing:
    id: str
    td: dict[str, Any]
    anonymous: bool
    own: bool = False
    size: int = 0
    """Characters of the stored JSON text (what the TD costs the store's byte budget)."""


def _utc(moment: datetime | None) -> datetime | None:
    return None if moment is None else moment.astimezone(UTC)


class ThingStore:
    """``create_tables=False``: the tables are someone else's to create (the hub's Alembic
    migrations); opening checks they are there instead of creating them."""

    def __init__(self, engine: Engine | str, create_tables: bool = True) -> None:
        self.owns_engine = isinstance(engine, str)
        self.create_tables = create_tables
        self.engine = make_engine(engine) if isinstance(engine, str) else engine
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="wott-directory-db")

    async def _run(self, fn: Callable[..., T], *args: Any) -> T:
        return await asyncio.get_running_loop().run_in_executor(self._executor, fn, *args)

    # -- start-up --------------------------------------------------------------
    async def open(self, event_retention: int) -> tuple[list[StoredThing], list[Event]]:
        return await self._run(self._open, event_retention)

    def _open(self, event_retention: int) -> tuple[list[StoredThing], list[Event]]:
        if self.create_tables:
            create_schema(self.engine)
        else:
            tables = set(inspect(self.engine).get_table_names())
            missing = sorted({ThingRow.__tablename__, EventRow.__tablename__} - tables)
            if missing:
                raise RuntimeError(f"the directory's tables {', '.join(missing)} are missing from "
                                   f"{self.engine.url!r}: run the migrations that create them first")
        with self.engine.connect() as conn:
            rows_td = conn.execute(select(ThingRow.id, ThingRow.td, ThingRow.anonymous, ThingRow.own))
            things = [StoredThing(r.id, json.loads(r.td), r.anonymous, r.own, len(r.td)) for r in rows_td]
            rows = conn.execute(select(EventRow).order_by(EventRow.id.desc()).limit(event_retention)).all()
        events = [Event(r.id, r.type, r.thing_id, json.loads(r.data) if r.data else None, len(r.data or ""))
                  for r in reversed(rows)]
        return things, events

    # -- writes ----------------------------------------------------------------
    async def write(self, upserts: Iterable[dict[str, Any]] = (), deletes: Iterable[str] = (),
                    events: Iterable[Event] = (), new_ids: Iterable[str] = ()) -> None:
        """One transaction: rows to insert (ids in ``new_ids``) or update, ids to delete, events."""
        await self._run(self._write, list(upserts), list(deletes), list(events), set(new_ids))

    def _write(self, upserts: list[dict[str, Any]], deletes: list[str], events: list[Event],
               new_ids: set[str]) -> None:
        with self.engine.begin() as conn:
            inserts = [u for u in upserts if u["id"] in new_ids]
            updates = [u for u in upserts if u["id"] not in new_ids]
            if inserts:
                conn.execute(insert(ThingRow), [self._row(u) for u in inserts])
            for u in updates:
                row = self._row(u)
                conn.execute(update(ThingRow).where(ThingRow.id == row.pop("id")).values(**row))
            if deletes:
                conn.execute(delete(ThingRow).where(ThingRow.id.in_(deletes)))
            if events:
                conn.execute(insert(EventRow), [
                    {"id": e.id, "type": e.type, "thing_id": e.thing_id, "created": datetime.now(UTC),
                     "data": None if e.data is None else json.dumps(e.data, ensure_ascii=False)}
                    for e in events])

    @staticmethod
    def _row(u: dict[str, Any]) -> dict[str, Any]:
        return {"id": u["id"], "td": json.dumps(u["td"], ensure_ascii=False),
                "anonymous": u.get("anonymous", False), "own": u.get("own", False),
                "created": _utc(u["created"]),
                "modified": _utc(u["modified"]), "expires": _utc(u.get("expires"))}

    async def trim_events(self, keep_after: int) -> None:
        await self._run(self._trim, keep_after)

    def _trim(self, keep_after: int) -> None:
        with self.engine.begin() as conn:
            conn.execute(delete(EventRow).where(EventRow.id <= keep_after))

    async def close(self) -> None:
        self._executor.shutdown(wait=True)
        if self.owns_engine:
            self.engine.dispose()


class Catalogue:
    def __init__(self) -> None:
        self.things: dict[str, Enriched] = {}
        self.sizes: dict[str, int] = {}  # bytes of each stored TD's JSON
        self.stored_bytes = 0
        self.anonymous: set[str] = set()
        self.own: set[str] = set()  # the directory's own TD(s)
        self.held: set[str] = set()  # written by the embedder: HTTP clients may not change them
        self.unsearchable: set[str] = set()  # stored before the depth limit, deeper than it
        self.ids: list[str] = []  # ascending (code point order): what ``page`` serves
        self._array: list[dict[str, Any]] | None = None
        self._boot = secrets.token_hex(4)
        self._version = 0

    def load(self, things: Iterable[StoredThing]) -> None:
        """What the database holds, at start."""
        for t in things:
            self.things[t.id] = Enriched.from_stored(t.td)
            self.sizes[t.id] = t.size
            self.stored_bytes += t.size
            if t.anonymous:
                self.anonymous.add(t.id)
            if t.own:
                self.own.add(t.id)
            if json_depth(t.td, MAX_TD_DEPTH) > MAX_TD_DEPTH:
                self.unsearchable.add(t.id)
        self.ids = sorted(self.things)

    @property
    def etag(self) -> str:
        """Changes whenever the collection does (any create, update, refresh, delete)."""
        return f"{self._boot}-{self._version}"

    def page(self, offset: int, limit: int) -> list[dict[str, Any]]:
        return [self.things[i].td for i in self.ids[offset:offset + limit]]

    def snapshot(self) -> list[dict[str, Any]]:
        """The array JSONPath queries run on (shared, never mutated: treat as read-only)."""
        if self._array is None:
            skip = self.unsearchable
            self._array = [self.things[i].td for i in self.ids if i not in skip]
        return self._array

    def row(self, thing_id: str, rec: Enriched, anonymous: bool) -> dict[str, Any]:
        """What ``ThingStore.write`` stores for ``rec``."""
        return {"id": thing_id, "td": rec.td, "anonymous": anonymous, "own": thing_id in self.own,
                "created": rec.created, "modified": rec.modified, "expires": rec.expires}

    def stored(self, thing_id: str, rec: Enriched, size: int, anonymous: bool) -> None:
        """``rec`` (``size`` bytes of JSON) is in the database now."""
        new = thing_id not in self.things
        self.things[thing_id] = rec
        self.stored_bytes += size - self.sizes.get(thing_id, 0)
        self.sizes[thing_id] = size
        self.unsearchable.discard(thing_id)  # a TD written now passed the depth check
        if new:
            bisect.insort(self.ids, thing_id)
            if anonymous:
                self.anonymous.add(thing_id)
        self._changed()

    def removed(self, thing_id: str) -> None:
        """``thing_id`` is deleted from the database now."""
        del self.things[thing_id]
        self.stored_bytes -= self.sizes.pop(thing_id, 0)
        self.anonymous.discard(thing_id)
        self.held.discard(thing_id)
        self.unsearchable.discard(thing_id)
        del self.ids[bisect.bisect_left(self.ids, thing_id)]
        self._changed()

    def _changed(self) -> None:
        self._version += 1
        self._array = None
