"""How a batch's rows go into the events table, in one transaction with the reservations it moves.

The fastest way each driver offers: PostgreSQL through psycopg 3 takes binary ``COPY``
(``_copy_rows``); a driver with a positional paramstyle (sqlite3, psycopg's others) takes
multi-row INSERTs of tuples; any other, SQLAlchemy's executemany. Used by the writer's own
thread and by its batch process (``batch_process.py``): the same rows, the same statements.
"""

from __future__ import annotations

import itertools
import sqlite3
import struct
from collections.abc import Callable

import sqlalchemy as sa
from sqlalchemy.engine import Engine

from .models import EventRow, ThingRow

__all__ = ["DATA_ERRORS", "Inserter", "Prepared", "Row", "copy_data", "one_line", "positional_insert"]

COLUMNS = ("thing_key", "seq", "t_ns", "kind", "name", "data")
Row = tuple[int, int, int, int, str, bytes]  # the values of COLUMNS
Prepared = tuple[list[Row], bytearray]  # a batch's rows and their COPY data (copy_data)

_COPY_HEAD = struct.Struct(">hiiiqiqih")
"""A binary COPY row up to its name: the field count, then each field's length and value for
``thing_key`` int4, ``seq`` int8, ``t_ns`` int8, ``kind`` int2 (models.EventRow)."""
_COPY_LEN = struct.Struct(">i")
_COPY_SIGNATURE = b"PGCOPY\n\xff\r\n\x00" + bytes(8)  # then flags and header extension length, 0
_COPY_TRAILER = b"\xff\xff"  # a field count of -1

DATA_ERRORS = (sa.exc.IntegrityError, sa.exc.DataError)
"""Errors about the rows themselves: retrying the same rows can never succeed; isolate them."""


def positional_insert(engine: Engine, table: str, columns: tuple[str, ...], rows: int = 1) -> str | None:
    """An INSERT of ``rows`` rows in the driver's own positional paramstyle, taking the rows'
    values as one flat tuple; None if the paramstyle is not positional (use executemany).

    SQLAlchemy's Core insert would build a dict per row and process each value in
    Python; tuples go straight to the driver (3-4x faster on SQLite). Many rows per
    statement matter as much: the sqlite3 module releases the GIL around each
    statement step, and a thread that gets the GIL back only after the event loop's
    switch interval (5 ms) would take seconds to insert a batch row by row while
    holding the database's write lock, starving every other writer.
    """
    style = engine.dialect.paramstyle
    n = len(columns)
    if style == "qmark":
        groups = ["(" + ", ".join(["?"] * n) + ")"] * rows
    elif style in ("format", "pyformat"):
        groups = ["(" + ", ".join(["%s"] * n) + ")"] * rows
    elif style in ("numeric", "numeric_dollar"):
        mark = ":" if style == "numeric" else "$"
        groups = ["(" + ", ".join(f"{mark}{r * n + i + 1}" for i in range(n)) + ")" for r in range(rows)]
    else:  # named: not positional
        return None
    return f"INSERT INTO {table} ({', '.join(columns)}) VALUES {', '.join(groups)}"


def _named_insert(table: str, columns: tuple[str, ...]) -> str:
    return f"INSERT INTO {table} ({', '.join(columns)}) VALUES ({', '.join(':' + c for c in columns)})"


def _copy_rows(conn: sa.Connection, table: str, rows: list[Row],
               meanwhile: Callable[[], bool] | None = None, data: bytearray | None = None) -> None:
    """PostgreSQL through psycopg 3: ``COPY ... FROM STDIN`` in the batch's transaction.

    A multi-row INSERT makes psycopg adapt every parameter in Python and PostgreSQL parse
    a statement of 6,000 placeholders: ~6,000 rows/s measured; COPY streams the rows at many
    times that. The batch's binary COPY data is built in one buffer (``copy_data``: half the
    CPU of psycopg's ``write_row`` per row) and handed to libpq at once; it sends what the socket
    takes, and between ``meanwhile``'s steps (the next batch's encoding) more is pushed in, so
    that the server always has data while this thread computes.
    A row the database refuses fails the COPY as a whole, raised as SQLAlchemy's error class
    for it (IntegrityError, DataError...), so ``_write_isolating`` halves the batch exactly as
    for an INSERT; a number out of its column's range is a DataError before anything is sent.
    """
    sql = f"COPY {table} ({', '.join(COLUMNS)}) FROM STDIN (FORMAT BINARY)"  # ~15 % over text
    import psycopg  # loaded already: the engine's driver
    from psycopg.copy import LibpqWriter

    try:
        if data is None:
            data = copy_data(rows)
    except struct.error as e:  # what PostgreSQL would refuse too (int4/int8/int2 columns)
        raise sa.exc.DataError(sql, None, psycopg.DataError(f"a value out of range: {e}")) from None
    dbapi_conn = conn.connection.dbapi_connection
    assert isinstance(dbapi_conn, psycopg.Connection)
    try:
        with dbapi_conn.cursor() as cur, \
                cur.copy(sql, writer=LibpqWriter(cur, flush_threshold=1 << 62)) as copy:
            copy.write(data)  # into libpq's buffer (this threshold: never waits), partly sent
            pgconn = dbapi_conn.pgconn
            while pgconn.flush() == 1 and meanwhile is not None and meanwhile():
                pass  # the socket took more; a step done: push more (the rest at the COPY's end)
    except conn.dialect.loaded_dbapi.Error as e:
        raise sa.exc.DBAPIError.instance(sql, None, e, conn.dialect.loaded_dbapi.Error) from None


def copy_data(rows: list[Row]) -> bytearray:
    """The rows in PostgreSQL's binary COPY format, signature to trailer: the bytes psycopg's
    ``write_row`` sends for them with the column types int4, int8, int8, int2, varchar, bytea."""
    head, length = _COPY_HEAD.pack, _COPY_LEN.pack
    names: dict[str, bytes] = {}  # a handful of affordance names: each encoded once
    out = bytearray(_COPY_SIGNATURE)
    for key, seq, t_ns, kind, name, data in rows:
        field = names.get(name)
        if field is None:
            text = name.encode()
            field = names[name] = length(len(text)) + text
        out += head(6, 4, key, 8, seq, 8, t_ns, 2, kind)
        out += field
        out += length(len(data))
        out += data
    out += _COPY_TRAILER
    return out


class Inserter:
    """The statements for this engine's driver, chosen once: ``commit`` writes a batch."""

    def __init__(self, engine: Engine) -> None:
        self.engine = engine
        # rows per statement: SQLite before 3.32 allows 999 parameters, later 32766
        max_params = 999 if engine.dialect.name == "sqlite" and sqlite3.sqlite_version_info < (3, 32) \
            else 30_000
        self._chunk = max(1, min(1000, max_params // len(COLUMNS)))
        self._insert_full = positional_insert(engine, EventRow.__tablename__, COLUMNS, self._chunk)
        self.copy = engine.dialect.name == "postgresql" and engine.dialect.driver == "psycopg"

    def commit(self, rows: list[Row], reserve: list[tuple[int, int]],
               meanwhile: Callable[[], bool] | None = None, copy: bytearray | None = None) -> None:
        """One transaction: ``rows``, and each ``(thing_key, seq_reserved)`` of ``reserve``;
        ``meanwhile``/``copy``: ``_copy_rows``'s (PostgreSQL)."""
        things = ThingRow.__table__
        with self.engine.begin() as conn:
            self._insert(conn, rows, meanwhile, copy)
            for key, reserved in reserve:
                conn.execute(things.update().where(things.c.key == key).values(seq_reserved=reserved))

    def _insert(self, conn: sa.Connection, rows: list[Row], meanwhile: Callable[[], bool] | None,
                copy: bytearray | None) -> None:
        table = EventRow.__tablename__
        if self.copy:
            _copy_rows(conn, table, rows, meanwhile, copy)
            return
        if self._insert_full is None:  # a driver with a named paramstyle: executemany
            conn.exec_driver_sql(_named_insert(table, COLUMNS), [dict(zip(COLUMNS, r, strict=True))
                                                                  for r in rows])
            return
        chunk = self._chunk
        for i in range(0, len(rows), chunk):
            part = rows[i:i + chunk]
            sql = self._insert_full if len(part) == chunk else positional_insert(
                self.engine, table, COLUMNS, len(part))
            assert sql is not None  # positional, as _insert_full is
            try:
                conn.exec_driver_sql(sql, tuple(itertools.chain.from_iterable(part)))
            except OverflowError as e:  # sqlite3 binding an int beyond int64: that row's data error
                raise sa.exc.DataError(sql, None, OverflowError(f"a value out of range: {e}")) from None


def one_line(e: BaseException) -> str:
    """The driver's message without SQLAlchemy's statement dump and background link."""
    text = str(getattr(e, "orig", None) or e)
    return text.splitlines()[0] if text else type(e).__name__
