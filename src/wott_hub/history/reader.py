"""Read history: what is recorded, ranges in sequence order, resume backlogs.

A Thing's records are read in pages by primary key (thing, seq) ranges,
which on SQLite is the table's own clustered order (sequential reads); a time
range is first turned into a seq range through ``ix_events_thing_time``.
Within a Thing, time order is seq order: the processor rejects frames that go
back in time. Pages are separate short transactions, so a long replay never
holds a read snapshot open (SQLite could not checkpoint its WAL meanwhile). On SQLite a page is
read as one row whose columns SQLite joined (``sqlite.JOINED``: no Python object per row). Every
read gives ``Record``s (``storage.StorageReader``): a page is decoded as ``Columns``, then made
records in one ``map``; ``columns`` gives the page as it is, to a replay that makes each record
as it emits it.

Contract: a read the database fails (a corrupted page, a file that is not a
database, a lost connection) raises ``wott_hub.errors.HistoryError`` naming
the database, and is noted in its ``DatabaseState`` (the writer's health
turns "degraded"); it never ends as an empty result.
"""

from __future__ import annotations

import asyncio
import functools
import json
import sqlite3
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import TYPE_CHECKING, Any, ParamSpec, TypeVar

import sqlalchemy as sa
from sqlalchemy.engine import Engine

from wott_hub.errors import HistoryError, NotFound
from wott_hub.events.record import Record

from .db import describe
from .db_errors import database_error, driver_message, is_database_error
from .models import EventRow, ThingRow
from .state import state_of
from .storage import Columns, ThingSummary

if TYPE_CHECKING:  # NumPy, imported by the reads that decode pages: listing what is recorded needs none
    from .sqlite import JoinedPage

__all__ = ["FIRST_PAGE", "HistoryReader"]

FIRST_PAGE = 1000
"""Records in the first page of a range (``HistoryReader.columns``), the rest in full pages."""

_E = EventRow.__table__
_T = ThingRow.__table__

_P = ParamSpec("_P")
_R = TypeVar("_R")
_Page = TypeVar("_Page")


def _guarded(method: Callable[_P, _R]) -> Callable[_P, _R]:
    """Database errors of a read become a HistoryError (and are noted in the database's state)."""

    @functools.wraps(method)
    def wrapper(*args: _P.args, **kwargs: _P.kwargs) -> _R:
        self: HistoryReader = args[0]  # type: ignore[assignment]  # a method: args[0] is self
        try:
            return method(*args, **kwargs)
        except Exception as e:  # SQLAlchemy's, and the driver's own from the raw cursors used here
            if is_database_error(e):
                raise self._failed(e) from None
            raise

    return wrapper


def _seq_range(key: int, after: int, upto: int, limit: int) -> sa.Select[int, int, int, str, bytes]:
    """(seq, t_ns, kind, name, data) of the Thing ``key`` with after < seq <= upto, in seq order."""
    return (sa.select(_E.c.seq, _E.c.t_ns, _E.c.kind, _E.c.name, _E.c.data)
            .where(_E.c.thing_key == key, _E.c.seq > after, _E.c.seq <= upto)
            .order_by(_E.c.seq).limit(limit))


def _columns(rows: Sequence[Sequence[Any]]) -> Columns:
    """(seq, t_ns, kind, name, stored) rows, not empty, as columns with the text sent live for
    ``stored``: the packets of the rows decoded together, the columns moved by C-level ``zip``s."""
    from .codec import decode_many

    seqs, times, kinds, names, stored = zip(*rows, strict=True)
    return Columns(seqs, times, kinds, names, decode_many(stored, times))


def _joined_columns(page: JoinedPage) -> Columns:
    from .codec import decode_joined

    return Columns(page.seqs.tolist(), page.times.tolist(), page.kinds.tolist(), page.names,
                    decode_joined(page.joined, page.sizes, page.times))


def _joined_numbers(thing: str, page: JoinedPage) -> list[Record]:
    from .numbers import numbered_records, numbers_joined

    numbers = numbers_joined(page.joined, page.sizes, page.times, page.names, page.kinds)
    return numbered_records(thing, page.seqs, page.kinds, page.names, page.times, numbers)


def _rows_numbers(thing: str, rows: Sequence[Sequence[Any]]) -> list[Record]:
    from .numbers import numbered_records, numbers_many

    seqs, times, kinds, names, stored = zip(*rows, strict=True)
    return numbered_records(thing, seqs, kinds, names, times, numbers_many(stored, times, names, kinds))


class HistoryReader:
    """``storage.StorageReader`` on SQLite and PostgreSQL, and the plane's ``HistorySource``."""

    def __init__(self, engine: Engine) -> None:
        self.engine = engine
        self._keys: dict[str, int] = {}
        self.state = state_of(engine)

    @property
    def failure(self) -> str:
        return self.state.corrupted or self.state.forwarding

    def _failed(self, e: BaseException) -> HistoryError:
        self.state.read_failed(driver_message(e))
        return database_error(e, f"cannot read the history database {describe(self.engine.url)!r}")

    @_guarded
    def _fetch(self, stmt: sa.Select[int, int, int, str, bytes]) -> list[tuple[Any, ...]]:
        """Rows as plain tuples straight from the driver's cursor.

        The statement is compiled by SQLAlchemy for the engine's dialect (so the
        same code runs on SQLite and PostgreSQL); skipping SQLAlchemy's result
        rows reads ~1.7x faster, which is most of a replay's time.
        """
        with self.engine.connect() as conn:
            compiled = stmt.compile(dialect=conn.dialect)
            params = compiled.params
            order = compiled.positiontup  # set when the driver's paramstyle is positional
            args = tuple(params[k] for k in order) if compiled.positional and order is not None else params
            raw = conn.connection.driver_connection
            assert raw is not None  # an open connection has its driver's
            cur = raw.cursor()
            try:
                cur.execute(str(compiled), args)
                rows: list[tuple[Any, ...]] = cur.fetchall()
                return rows
            finally:
                cur.close()

    @_guarded
    def key(self, thing: str) -> int | None:
        key = self._keys.get(thing)
        if key is None:
            with self.engine.connect() as conn:
                key = conn.execute(sa.select(_T.c.key).where(_T.c.id == thing)).scalar()
            if key is not None:
                self._keys[thing] = key
        return key

    def recorded(self, thing: str) -> bool:
        return self.key(thing) is not None

    # --- what is recorded -----------------------------------------------------------

    @_guarded
    def things(self, *, count: bool = True) -> list[ThingSummary]:
        """Every recorded Thing with its first and last seq and time: one statement, each bound an
        index's first or last entry (``uq_events_thing_key``, ``ix_events_thing_time``), so it
        costs the same on a minute of history as on a day. ``count``: the exact number of
        records too, which no index holds: a scan of the Thing's index entries (~0.1 s per
        million on SQLite); without it, ``count`` is None."""
        def end(col: Any, last: bool) -> Any:
            return (sa.select(col).where(_E.c.thing_key == _T.c.key)
                    .order_by(col.desc() if last else col).limit(1).scalar_subquery())

        q = sa.select(_T.c.key, _T.c.id, _T.c.title, _T.c.family, end(_E.c.seq, False), end(_E.c.seq, True),
                      end(_E.c.t_ns, False), end(_E.c.t_ns, True)).order_by(_T.c.id)
        out = []
        with self.engine.connect() as conn:
            for key, tid, title, family, s0, s1, t0, t1 in conn.execute(q).all():
                n: int | None = None
                if s0 is None:
                    n = 0
                elif count:
                    n = conn.execute(sa.select(sa.func.count()).select_from(_E)
                                     .where(_E.c.thing_key == key)).scalar_one()
                out.append(ThingSummary(tid, title, family, n, s0, s1, t0, t1))
        return out

    @_guarded
    def thing_info(self, thing: str) -> dict[str, Any] | None:
        with self.engine.connect() as conn:
            row = conn.execute(sa.select(_T.c.title, _T.c.family, _T.c.td, _T.c.static_values)
                               .where(_T.c.id == thing)).first()
        if row is None:
            return None
        title, family, td, static = row
        return {"id": thing, "title": title, "family": family,
                "td": json.loads(td) if td else None, "static_values": json.loads(static) if static else {}}

    @_guarded
    def first_time(self, things: Sequence[str], t_from_ns: int | None) -> int | None:
        best = None
        for thing in things:
            key = self.key(thing)
            if key is None:
                continue
            q = sa.select(sa.func.min(_E.c.t_ns)).where(_E.c.thing_key == key)
            if t_from_ns is not None:
                q = q.where(_E.c.t_ns >= t_from_ns)
            with self.engine.connect() as conn:
                t = conn.execute(q).scalar()
            if t is not None and (best is None or t < best):
                best = t
        return best

    # --- resume backlog (the event plane's HistorySource) ---------------------------

    def rows(self, thing: str, after: int, upto: int, interest: tuple[int, str | None],
             limit: int) -> tuple[list[Record], int]:
        key = self.key(thing)
        if key is None:
            return [], upto
        kind, name = interest
        rows = self._fetch(_seq_range(key, after, upto, limit))
        reached = rows[-1][0] if len(rows) == limit else upto
        wanted = [r for r in rows if r[2] == kind and (name is None or r[3] == name)]
        return (_columns(wanted).records(thing) if wanted else []), reached

    async def fetch(self, thing: str, after: int, upto: int, interest: tuple[int, str | None],
                    limit: int) -> tuple[list[Record], int]:
        return await asyncio.to_thread(self.rows, thing, after, upto, interest, limit)

    # --- ranges (export, replay, the hub's history API) -----------------------------

    @_guarded
    def seq_range(self, thing: str, t_from_ns: int | None = None,
                  t_to_ns: int | None = None) -> tuple[int, int] | None:
        """First and last seq of ``thing`` within [t_from, t_to]; None if nothing is there.

        An open side is the end of the seq index, not the seq of the earliest or latest time: a
        Thing's records are numbered as they are published, but stamped with the time of what
        they describe, and that can go back (a ``rawImageRecorded`` event carries its frame's
        time and is published once encoded, after records of later frames). The latest record
        by time was then not the last one, and a read without bounds left the image out. A
        bounded side is still found by the time index (one index step, not a scan of the range):
        a record stamped before records published ahead of it can fall outside a bounded range's
        seqs at that side (docs/history.md, "Reading by time")."""
        key = self.key(thing)
        if key is None:
            return None
        with self.engine.connect() as conn:
            q = sa.select(_E.c.seq).where(_E.c.thing_key == key)
            if t_from_ns is None:
                q0 = q.order_by(_E.c.seq)
            else:
                q0 = q.where(_E.c.t_ns >= t_from_ns).order_by(_E.c.t_ns, _E.c.seq)
            if t_to_ns is None:
                q1 = q.order_by(_E.c.seq.desc())
            else:
                q1 = q.where(_E.c.t_ns <= t_to_ns).order_by(_E.c.t_ns.desc(), _E.c.seq.desc())
            lo = conn.execute(q0.limit(1)).scalar()
            hi = conn.execute(q1.limit(1)).scalar()
        if lo is None or hi is None or lo > hi:
            return None
        return lo, hi

    @_guarded
    def record_page(self, thing: str, *, t_from_ns: int | None = None, t_to_ns: int | None = None,
                    names: list[str] | None = None, after: int = 0, limit: int = 1000) -> list[Record]:
        """Paging is by sequence number (``after``): a client asks again with the last seq it got
        until a page comes back shorter than its limit. The time range is turned into a seq range
        once (``seq_range``, through the time index); the name filter runs in SQL."""
        key = self.key(thing)
        if key is None:
            raise NotFound(f"no recorded device {thing!r}")
        bounds = self.seq_range(thing, t_from_ns, t_to_ns)
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
        with self.engine.connect() as conn:
            rows = conn.execute(q.order_by(_E.c.seq).limit(limit)).all()
        return _columns(rows).records(thing) if rows else []

    @_guarded
    def last_at(self, thing: str, name: str, t_ns: int, limit: int = 1) -> list[Record]:
        """One step back along ``ix_events_thing_time`` from ``t_ns``, the name filtered as it goes: a
        few index entries for a name recorded often, a scan back to the Thing's first record for one
        never recorded before ``t_ns``."""
        key = self.key(thing)
        if key is None:
            return []
        q = (sa.select(_E.c.seq, _E.c.t_ns, _E.c.kind, _E.c.name, _E.c.data)
             .where(_E.c.thing_key == key, _E.c.t_ns <= t_ns, _E.c.name == name)
             .order_by(_E.c.t_ns.desc(), _E.c.seq.desc()).limit(limit))
        with self.engine.connect() as conn:
            rows = conn.execute(q).all()
        return _columns(rows).records(thing) if rows else []

    def pages(self, thing: str, t_from_ns: int | None = None, t_to_ns: int | None = None,
              names: list[str] | None = None, page: int = 20_000, *,
              numbers: bool = False) -> Iterator[list[Record]]:
        if numbers:  # history/numbers.py
            yield from self._read(thing, t_from_ns, t_to_ns, names, page,
                                  functools.partial(_joined_numbers, thing),
                                  functools.partial(_rows_numbers, thing))
            return
        for cols in self.columns(thing, t_from_ns, t_to_ns, names, page):
            yield cols.records(thing)

    def columns(self, thing: str, t_from_ns: int | None = None, t_to_ns: int | None = None,
                names: list[str] | None = None, page: int = 20_000) -> Iterator[Columns]:
        """The pages as ``Columns`` (``_read``)."""
        return self._read(thing, t_from_ns, t_to_ns, names, page, _joined_columns, _columns)

    def _read(self, thing: str, t_from_ns: int | None, t_to_ns: int | None, names: list[str] | None,
              page: int, of_joined: Callable[[JoinedPage], _Page],
              of_rows: Callable[[Sequence[Sequence[Any]]], _Page]) -> Iterator[_Page]:
        """``columns``' pages, each made by ``of_joined`` or ``of_rows``.

        On SQLite each page is one row of ``sqlite.JOINED``, the next one read in a thread of its
        own while this one is decoded and used (a query is one step of SQLite, run without the
        GIL: it overlaps the Python work); elsewhere, and for a page ``JOINED`` cannot give, the
        driver's rows transposed by one C-level ``zip``. The first page is at most ``FIRST_PAGE``
        records: a replay or an export starts as soon as those are read, not a whole page later."""
        bounds = self.seq_range(thing, t_from_ns, t_to_ns)
        if bounds is None:
            return
        key = self.key(thing)
        if key is None:  # never: seq_range found records of it
            return
        lo, hi = bounds
        cursor = lo - 1
        ahead = None
        size = min(page, FIRST_PAGE)
        pool = ThreadPoolExecutor(1, thread_name_prefix="history-page") if self._joins else None
        try:
            while cursor < hi:
                if pool is not None and ahead is None:
                    ahead = pool.submit(self._joined, key, cursor, hi, t_from_ns, t_to_ns, names, size)
                    size = page
                joined = ahead.result() if ahead is not None else None
                ahead = None
                if joined is not None:
                    if not len(joined.seqs):
                        return
                    cursor = int(joined.seqs[-1])
                    if cursor < hi and pool is not None:
                        ahead = pool.submit(self._joined, key, cursor, hi, t_from_ns, t_to_ns, names, page)
                    yield of_joined(joined)
                    continue
                rows = self._fetch(_seq_range(key, cursor, hi, size))
                size = page
                if not rows:
                    return
                cursor = rows[-1][0]
                if t_from_ns is not None or t_to_ns is not None or names:
                    lo_t = t_from_ns if t_from_ns is not None else -1
                    hi_t = t_to_ns if t_to_ns is not None else 1 << 63
                    rows = [r for r in rows if lo_t <= r[1] <= hi_t and (not names or r[3] in names)]
                if rows:
                    yield of_rows(rows)
        finally:
            if pool is not None:
                pool.shutdown(wait=False, cancel_futures=True)

    @property
    def _joins(self) -> bool:
        """Whether pages are read as ``sqlite.JOINED`` (SQLite)."""
        return self.engine.dialect.name == "sqlite"

    @_guarded
    def _joined(self, key: int, after: int, upto: int, t_from_ns: int | None, t_to_ns: int | None,
                names: list[str] | None, limit: int) -> JoinedPage | None:
        lo_t = t_from_ns if t_from_ns is not None else -1 << 63
        hi_t = t_to_ns if t_to_ns is not None else (1 << 63) - 1
        from .sqlite import joined_page

        with self.engine.connect() as conn:
            raw = conn.connection.driver_connection
            assert isinstance(raw, sqlite3.Connection)
            return joined_page(raw, key, after, upto, lo_t, hi_t, names, limit)
