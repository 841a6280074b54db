"""The PostgreSQL engine: a batch's rows as binary ``COPY`` through psycopg 3, streamed while the
writer works on the next batch.

A multi-row INSERT makes psycopg adapt every parameter in Python and PostgreSQL parse a
statement of 6,000 placeholders: ~6,000 rows/s measured; COPY streams the rows at many times
that. The batch's binary COPY data is built in one buffer (``copy_data``: half the CPU of
psycopg's ``write_row`` per row), ahead of the write when the writer prepares the batch, and
handed to libpq at once; it sends what the socket takes, and between ``meanwhile``'s steps (the
writer encoding its next batch) more is pushed in, so that the server always has data while the
writer's thread computes: this engine ``overlaps``. Another PostgreSQL driver gets
``SqlStorage``'s INSERTs.

A row the database refuses fails the COPY as a whole, as ``RecordRefused`` (``db_errors.py``), so
the writer halves the batch exactly as for an INSERT; a number out of its column's range is
refused before anything is sent.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

import sqlalchemy as sa
from sqlalchemy.engine import Engine

from wott_hub.errors import RecordRefused
from wott_hub.events.record import Record

from .lease import DEFAULT_HUB_ID, LEASE_STALE_S
from .models import EventRow
from .sql import COLUMNS, SqlStorage
from .storage import Prepared, Row, Step

__all__ = ["PostgresStorage", "copy_data"]

_COPY_HEAD = struct.Struct(">hiiiqiqih")
"""A binary COPY row up to its name: the field count, then each field's length and value for
``thing_key`` int4, ``seq`` int8, ``t_ns`` int8, ``kind`` int2 (models.EventRow)."""
_COPY_LEN = struct.Struct(">i")
_COPY_SIGNATURE = b"PGCOPY\n\xff\r\n\x00" + bytes(8)  # then flags and header extension length, 0
_COPY_TRAILER = b"\xff\xff"  # a field count of -1
_COPY = f"COPY {EventRow.__tablename__} ({', '.join(COLUMNS)}) FROM STDIN (FORMAT BINARY)"  # ~15 % over text


def copy_data(rows: list[Row]) -> bytearray:
    """The rows in PostgreSQL's binary COPY format, signature to trailer: the bytes psycopg's
    ``write_row`` sends for them with the column types int4, int8, int8, int2, varchar, bytea;
    ``RecordRefused`` for a number its column cannot hold (what PostgreSQL would refuse too)."""
    head, length = _COPY_HEAD.pack, _COPY_LEN.pack
    names: dict[str, bytes] = {}  # a handful of affordance names: each encoded once
    out = bytearray(_COPY_SIGNATURE)
    try:
        for key, seq, t_ns, kind, name, data in rows:
            field = names.get(name)
            if field is None:
                text = name.encode()
                field = names[name] = length(len(text)) + text
            out += head(6, 4, key, 8, seq, 8, t_ns, 2, kind)
            out += field
            out += length(len(data))
            out += data
    except struct.error as e:
        raise RecordRefused(f"a value out of range: {e}") from None
    out += _COPY_TRAILER
    return out


class PostgresStorage(SqlStorage):
    def __init__(self, engine: Engine, *, compact: bool = True, hub_id: str = DEFAULT_HUB_ID,
                 lease_stale_s: float = LEASE_STALE_S) -> None:
        super().__init__(engine, compact=compact, hub_id=hub_id, lease_stale_s=lease_stale_s)
        self.overlaps = engine.dialect.driver == "psycopg"  # COPY: another driver INSERTs

    def prepare(self, batch: Sequence[Record], payloads: list[bytes] | None = None) -> Prepared:
        rows = self._rows(batch, self.encode(batch) if payloads is None else payloads)
        return Prepared(rows, copy_data(rows) if self.overlaps else None)

    def _insert(self, conn: sa.Connection, batch: Prepared, meanwhile: Step | None) -> None:
        if not self.overlaps:
            super()._insert(conn, batch, meanwhile)
            return
        import psycopg  # loaded already: the engine's driver
        from psycopg.copy import LibpqWriter

        data = copy_data(batch.rows) if batch.wire is None else batch.wire
        dbapi_conn = conn.connection.dbapi_connection
        assert isinstance(dbapi_conn, psycopg.Connection)
        with dbapi_conn.cursor() as cur, \
                cur.copy(_COPY, writer=LibpqWriter(cur, flush_threshold=1 << 62)) as copy:
            copy.write(data)  # into libpq's buffer (this threshold: never waits), partly sent
            pgconn = dbapi_conn.pgconn
            while pgconn.flush() == 1 and meanwhile is not None and meanwhile():
                pass  # the socket took more; a step done: push more (the rest at the COPY's end)
