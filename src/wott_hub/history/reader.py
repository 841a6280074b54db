"""Read history: what is recorded, ranges in sequence order, resume backlogs.

A Thing's records are read in pages by primary key (thing, seq) ranges,
which on SQLite is the table's own clustered order (sequential reads); a time
range is first turned into a seq range through ``ix_events_thing_time``.
Within a Thing, time order is seq order: the processor rejects frames that go
back in time. Pages are separate short transactions, so a long replay never
holds a read snapshot open (SQLite could not checkpoint its WAL meanwhile). On SQLite a page is
read as one row whose columns SQLite joined (``_JOINED``: no Python object per record).

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
from dataclasses import dataclass
from typing import Any, NamedTuple, ParamSpec, TypeVar

import numpy as np
import numpy.typing as npt
import sqlalchemy as sa
from sqlalchemy.engine import Engine

from wott_hub.events.record import Record

from .codec import decode_joined, decode_many
from .db import HistoryError, describe
from .models import EventRow, ThingRow
from .state import state_of

__all__ = ["Columns", "HistoryReader", "ThingSummary", "decode_rows"]

_E = EventRow.__table__
_T = ThingRow.__table__


@dataclass(frozen=True)
class ThingSummary:
    id: str
    title: str
    family: str
    count: int
    first_seq: int | None
    last_seq: int | None
    first_t_ns: int | None
    last_t_ns: int | None

    def to_dict(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


_P = ParamSpec("_P")
_R = TypeVar("_R")


def _guarded(method: Callable[_P, _R]) -> Callable[_P, _R]:
    """Driver errors of a read become a HistoryError (and are noted in the database's state)."""

    @functools.wraps(method)
    def wrapper(*args: _P.args, **kwargs: _P.kwargs) -> _R:
        self: HistoryReader = args[0]  # type: ignore[assignment]  # a method: args[0] is self
        try:
            return method(*args, **kwargs)
        except (sa.exc.DBAPIError, sa.exc.OperationalError) as e:
            raise self._failed(e) from None
        except Exception as e:  # the DBAPI's own errors (PEP 249), raised by the raw cursor of _fetch
            if any(c.__name__ in ("DatabaseError", "InterfaceError") for c in type(e).__mro__):
                raise self._failed(e) from None
            raise

    return wrapper


def _seq_range(key: int, after: int, upto: int, limit: int) -> sa.Select[int, int, int, str, bytes]:
    """(seq, t_ns, kind, name, data) of the Thing ``key`` with after < seq <= upto, in seq order."""
    return (sa.select(_E.c.seq, _E.c.t_ns, _E.c.kind, _E.c.name, _E.c.data)
            .where(_E.c.thing_key == key, _E.c.seq > after, _E.c.seq <= upto)
            .order_by(_E.c.seq).limit(limit))


_JOINED = """SELECT count(*), group_concat(seq), group_concat(t_ns), group_concat(kind),
group_concat(name, char(0)), group_concat(length(data)), CAST(group_concat(data, '') || zeroblob(16) AS BLOB)
FROM (SELECT seq, t_ns, kind, name, data FROM events
      WHERE thing_key = ? AND seq > ? AND seq <= ? AND t_ns >= ? AND t_ns <= ?{names} ORDER BY seq LIMIT ?)"""
"""A page of ``_seq_range`` (its time and name filters too) as one row: each column's values
joined by SQLite, the payloads one after the other (16 NUL bytes after them: ``decode_joined``).
A row per record costs the driver ~1 µs in Python (a tuple, five objects, the lock taken back
after each step), most of a replay's reading; this is one step, run without the lock, and
strings that NumPy and ``str.split`` read in C. SQLite 3.40 has no ORDER BY within an aggregate:
the page is used only if its seqs come out ascending (= in seq order), else read row by row."""


class _Joined(NamedTuple):
    """A page of ``_JOINED`` checked, not yet decoded."""

    seqs: npt.NDArray[np.int64]
    times: npt.NDArray[np.int64]
    kinds: npt.NDArray[np.int64]
    names: list[str]
    sizes: npt.NDArray[np.int64]
    joined: bytes

    def decode(self) -> Columns:
        return Columns(self.seqs.tolist(), self.times.tolist(), self.kinds.tolist(), self.names,
                       decode_joined(self.joined, self.sizes, self.times))


def _joined_page(raw: sqlite3.Connection, key: int, after: int, upto: int, t_from_ns: int, t_to_ns: int,
                 names: list[str] | None, limit: int) -> _Joined | None:
    """The page of ``_JOINED`` (no seqs: nothing left); None where the page cannot be read so (a
    page beyond SQLite's longest value, seqs out of order, a payload stored as text that is not
    ASCII, whose ``length`` counts characters): the caller reads it row by row."""
    sql = _JOINED.format(names=f" AND name IN ({', '.join('?' * len(names))})" if names else "")
    cur = raw.cursor()
    try:
        cur.execute(sql, (key, after, upto, t_from_ns, t_to_ns, *(names or ()), limit))
        count, seqs, times, kinds, names_, sizes, joined = cur.fetchone()
    except sqlite3.DataError:  # longer than SQLITE_MAX_LENGTH
        return None
    finally:
        cur.close()
    if not count:
        empty = np.empty(0, np.int64)
        return _Joined(empty, empty, empty, [], empty, bytes(16))
    seq = np.fromstring(seqs, np.int64, sep=",")
    t_ns = np.fromstring(times, np.int64, sep=",")
    kind = np.fromstring(kinds, np.int64, sep=",")
    size = np.fromstring(sizes, np.int64, sep=",")
    name = names_.split("\0")
    if not (len(seq) == len(t_ns) == len(kind) == len(size) == len(name) == count) \
            or (np.diff(seq) <= 0).any() or int(size.sum()) + 16 != len(joined):
        return None
    return _Joined(seq, t_ns, kind, name, size, joined)


def decode_rows(rows: Sequence[Sequence[Any]]) -> list[tuple[int, int, int, str, str]]:
    """(seq, t_ns, kind, name, stored) rows with the text sent live for ``stored``; the packets
    of the rows are decoded together, the columns moved by C-level ``zip``s."""
    return list(zip(*_columns(rows), strict=True)) if rows else []


def _columns(rows: Sequence[Sequence[Any]]) -> Columns:
    """``decode_rows`` as ``Columns`` (``rows`` not empty)."""
    seqs, times, kinds, names, stored = zip(*rows, strict=True)
    return Columns(seqs, times, kinds, names, decode_many(stored, times))


class Columns(NamedTuple):
    """A page of records as columns, payloads decoded: what a replay walks with one ``zip``
    instead of a tuple built and unpacked per record (``HistoryReader.pages`` has the rows)."""

    seqs: Sequence[int]
    times: Sequence[int]
    kinds: Sequence[int]
    names: Sequence[str]
    data: list[str]


class HistoryReader:
    def __init__(self, engine: Engine) -> None:
        self.engine = engine
        self._keys: dict[str, int] = {}
        self.state = state_of(engine)

    @property
    def failure(self) -> str:
        """Why this database cannot be trusted to answer (known corrupted), else ""."""
        return self.state.corrupted

    def _failed(self, e: BaseException) -> HistoryError:
        cause = str(getattr(e, "orig", None) or e).splitlines()[0]
        self.state.read_failed(cause)
        return HistoryError(f"cannot read the history database {describe(self.engine.url)!r}: {cause}")

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

    # --- what is recorded -----------------------------------------------------------

    @_guarded
    def things(self) -> list[ThingSummary]:
        out = []
        with self.engine.connect() as conn:
            rows = conn.execute(sa.select(_T.c.key, _T.c.id, _T.c.title, _T.c.family).order_by(_T.c.id)).all()
            for key, tid, title, family in rows:
                count, s0, s1 = conn.execute(
                    sa.select(sa.func.count(), sa.func.min(_E.c.seq), sa.func.max(_E.c.seq))
                    .where(_E.c.thing_key == key)).one()
                t0 = t1 = None
                if count:
                    t0 = conn.execute(sa.select(_E.c.t_ns).where(_E.c.thing_key == key)
                                      .order_by(_E.c.t_ns).limit(1)).scalar()
                    t1 = conn.execute(sa.select(_E.c.t_ns).where(_E.c.thing_key == key)
                                      .order_by(_E.c.t_ns.desc()).limit(1)).scalar()
                out.append(ThingSummary(tid, title, family, count, s0, s1, t0, t1))
        return out

    @_guarded
    def thing_info(self, thing: str) -> dict[str, Any] | None:
        """Title, family, TD and static property values recorded for ``thing``."""
        with self.engine.connect() as conn:
            row = conn.execute(sa.select(_T.c.title, _T.c.family, _T.c.td, _T.c.static_values)
                               .where(_T.c.id == thing)).first()
        if row is None:
            return None
        title, family, td, static = row
        return {"id": thing, "title": title, "family": family,
                "td": json.loads(td) if td else None, "static_values": json.loads(static) if static else {}}

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
        return [Record(thing, s, k, n, t, d) for s, t, k, n, d in decode_rows(wanted)], reached

    async def fetch(self, thing: str, after: int, upto: int, interest: tuple[int, str | None],
                    limit: int) -> tuple[list[Record], int]:
        return await asyncio.to_thread(self.rows, thing, after, upto, interest, limit)

    # --- ranges (export, replay) ----------------------------------------------------

    @_guarded
    def seq_range(self, thing: str, t_from_ns: int | None = None,
                  t_to_ns: int | None = None) -> tuple[int, int] | None:
        """First and last seq of ``thing`` within [t_from, t_to]; None if nothing is there."""
        key = self.key(thing)
        if key is None:
            return None
        with self.engine.connect() as conn:
            q0 = sa.select(_E.c.seq).where(_E.c.thing_key == key)
            q1 = q0
            if t_from_ns is not None:
                q0 = q0.where(_E.c.t_ns >= t_from_ns)
            if t_to_ns is not None:
                q1 = q1.where(_E.c.t_ns <= t_to_ns)
            lo = conn.execute(q0.order_by(_E.c.t_ns, _E.c.seq).limit(1)).scalar()
            hi = conn.execute(q1.order_by(_E.c.t_ns.desc(), _E.c.seq.desc()).limit(1)).scalar()
        if lo is None or hi is None or lo > hi:
            return None
        return lo, hi

    def pages(self, thing: str, t_from_ns: int | None = None, t_to_ns: int | None = None,
              names: list[str] | None = None, page: int = 20_000) -> Iterator[list[tuple[Any, ...]]]:
        """Pages of (seq, t_ns, kind, name, data) in seq (= time) order; ``data`` the text sent live."""
        for cols in self.columns(thing, t_from_ns, t_to_ns, names, page):
            yield list(zip(*cols, strict=True))

    def columns(self, thing: str, t_from_ns: int | None = None, t_to_ns: int | None = None,
                names: list[str] | None = None, page: int = 20_000) -> Iterator[Columns]:
        """``pages`` as ``Columns``. On SQLite each page is one row of ``_JOINED``, the next one
        read in a thread of its own while this one is decoded and used (a query is one step of
        SQLite, run without the GIL: it overlaps the Python work); elsewhere, and for a page
        ``_JOINED`` cannot give, the driver's rows transposed by one C-level ``zip``."""
        bounds = self.seq_range(thing, t_from_ns, t_to_ns)
        if bounds is None:
            return
        key = self.key(thing)
        if key is None:  # never: seq_range found records of it
            return
        lo, hi = bounds
        cursor = lo - 1
        ahead = None
        pool = ThreadPoolExecutor(1, thread_name_prefix="history-page") if self._joins else None
        try:
            while cursor < hi:
                if pool is not None and ahead is None:
                    ahead = pool.submit(self._joined, key, cursor, hi, t_from_ns, t_to_ns, names, page)
                joined = ahead.result() if ahead is not None else None
                ahead = None
                if joined is not None:
                    if not len(joined.seqs):
                        return
                    cursor = int(joined.seqs[-1])
                    if cursor < hi and pool is not None:
                        ahead = pool.submit(self._joined, key, cursor, hi, t_from_ns, t_to_ns, names, page)
                    yield joined.decode()
                    continue
                rows = self._fetch(_seq_range(key, cursor, hi, page))
                if not rows:
                    return
                cursor = rows[-1][0]
                if t_from_ns is not None or t_to_ns is not None or names:
                    lo_t = t_from_ns if t_from_ns is not None else -1
                    hi_t = t_to_ns if t_to_ns is not None else 1 << 63
                    rows = [r for r in rows if lo_t <= r[1] <= hi_t and (not names or r[3] in names)]
                if rows:
                    yield _columns(rows)
        finally:
            if pool is not None:
                pool.shutdown(wait=False, cancel_futures=True)

    @property
    def _joins(self) -> bool:
        """Whether pages are read as ``_JOINED`` (SQLite)."""
        return self.engine.dialect.name == "sqlite"

    @_guarded
    def _joined(self, key: int, after: int, upto: int, t_from_ns: int | None, t_to_ns: int | None,
                names: list[str] | None, limit: int) -> _Joined | None:
        """``_joined_page`` (SQLite)."""
        lo_t = t_from_ns if t_from_ns is not None else -1 << 63
        hi_t = t_to_ns if t_to_ns is not None else (1 << 63) - 1
        with self.engine.connect() as conn:
            raw = conn.connection.driver_connection
            assert isinstance(raw, sqlite3.Connection)
            return _joined_page(raw, key, after, upto, lo_t, hi_t, names, limit)
