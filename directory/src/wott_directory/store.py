"""Persistence of TDs and events through SQLAlchemy, off the event loop.

Every write is one short transaction run on a single dedicated thread, so the
IOLoop (which the hub shares with its devices) never waits on the database,
and writes reach the database in the order the directory decided them.
"""

from __future__ import annotations

import asyncio
import json
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

__all__ = ["StoredThing", "ThingStore", "make_engine"]

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
