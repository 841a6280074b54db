"""The portable storage engine: the history tables through SQLAlchemy Core, on any dialect.

``SqlStorage`` is what the SQLite and PostgreSQL engines share (``sqlite.py``, ``postgres.py``
override only what their database does better or differently) and what any other dialect gets.
A batch's rows go in as multi-row INSERTs of tuples in the driver's own positional paramstyle
(sqlite3, psycopg's others), or SQLAlchemy's executemany for a named one; in one transaction
with the reservations the batch moves. Used by the writer's own thread and by its batch process
(``batch_process.py``): the same rows, the same statements.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Mapping, Sequence

import sqlalchemy as sa
from sqlalchemy.engine import Engine

from wott_hub.errors import Conflict, RecordRefused
from wott_hub.events.record import Record

from .codec import encode_records
from .db import describe
from .db_errors import translated
from .lease import DEFAULT_HUB_ID, LEASE_STALE_S, Lease, live_holder
from .models import EventRow, ThingRow
from .retention import Retention, apply_retention
from .state import state_of
from .storage import Prepared, Row, Step

__all__ = ["COLUMNS", "SqlStorage", "positional_insert"]

COLUMNS = ("thing_key", "seq", "t_ns", "kind", "name", "data")
"""The columns of a ``storage.Row``."""


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


class SqlStorage:
    """``storage.StorageWriter`` on any SQLAlchemy dialect. ``compact``: skin packets stored packed
    (``codec.py``); False stores every payload as its UTF-8 text (what revision 0005 stored; the
    storage benchmark's "before"). ``hub_id``: whose lease this writer takes (``lease.py``)."""

    overlaps = False
    max_params = 30_000
    """Parameters one statement may bind."""

    def __init__(self, engine: Engine, *, compact: bool = True, hub_id: str = DEFAULT_HUB_ID,
                 lease_stale_s: float = LEASE_STALE_S) -> None:
        self.engine = engine
        self.url = engine.url.render_as_string(hide_password=False)
        self.compact = compact
        self.keys: dict[str, int] = {}
        self.lease = Lease(engine, hub_id=hub_id, stale_s=lease_stale_s)
        self.state = state_of(engine)
        self._chunk = max(1, min(1000, self.max_params // len(COLUMNS)))  # rows per statement
        self._insert_full = positional_insert(engine, EventRow.__tablename__, COLUMNS, self._chunk)

    def describe(self) -> str:
        return describe(self.engine.url)

    # --- Things ---------------------------------------------------------------------------

    def register(self, thing: str, *, title: str, family: str, td: str | None, static_values: str | None,
                 ahead: int) -> int:
        things = ThingRow.__table__
        events = EventRow.__table__
        now = time.time_ns()
        with translated(f"cannot register {thing!r} in the history database {self.describe()!r}"), \
                self.engine.begin() as conn:
            # Write first: the transaction takes the write lock before it reads anything. (A
            # read first pins a WAL snapshot, and SQLite refuses at once, without waiting, to
            # turn a stale snapshot into a writer: "database is locked" under load.)
            conn.execute(things.update().where(things.c.id == thing).values(updated_ns=now))
            row = conn.execute(sa.select(things.c.key, things.c.seq_reserved, things.c.hub_id)
                               .where(things.c.id == thing)).first()
            mine = self.lease.hub_id
            if row is not None and row[2] not in (None, mine):
                other = live_holder(conn, row[2], self.lease.stale_s)
                if other is not None:
                    raise Conflict(f"the Thing {thing!r} is recorded in the history database "
                                   f"{self.describe()!r} by hub {row[2]!r} ({other}): two "
                                   "hubs cannot record the same Thing id; give each hub its own identity")
            values = {"title": title or thing, "family": family, "updated_ns": now, "hub_id": mine}
            if td is not None:
                values["td"] = td
            if static_values is not None:
                values["static_values"] = static_values
            if row is None:
                key = conn.execute(things.insert().values(id=thing, seq_reserved=0, **values)
                                   .returning(things.c.key)).scalar_one()
                reserved = 0
            else:
                key, reserved = row[0], row[1]
                conn.execute(things.update().where(things.c.key == key).values(**values))
            last = conn.execute(sa.select(sa.func.max(events.c.seq))
                                .where(events.c.thing_key == key)).scalar() or 0
            start = max(reserved, last)
            # reserve before the first record is handed out: a crash before the first
            # commit must not let the next run reuse numbers clients have seen
            conn.execute(things.update().where(things.c.key == key).values(seq_reserved=start + ahead))
        self.keys[thing] = key
        return int(start)

    def known(self, thing: str) -> bool:
        """Is ``thing`` in the database (its key then in ``keys``)? For records forwarded from the
        spool before the Thing is registered again (at the next start)."""
        if thing in self.keys:
            return True
        things = ThingRow.__table__
        with translated(), self.engine.connect() as conn:
            key = conn.execute(sa.select(things.c.key).where(things.c.id == thing)).scalar()
        if key is None:
            return False
        self.keys[thing] = int(key)
        return True

    def recorded(self, thing: str, lo: int, hi: int) -> set[int]:
        """The seqs in [lo, hi] of ``thing`` the database already has (``known`` Things only)."""
        events = EventRow.__table__
        with translated(), self.engine.connect() as conn:
            rows = conn.execute(sa.select(events.c.seq).where(events.c.thing_key == self.keys[thing])
                                .where(events.c.seq >= lo).where(events.c.seq <= hi)).scalars()
            return set(rows)

    def release(self, reserved: Mapping[str, int]) -> None:
        things = ThingRow.__table__
        with translated(f"cannot release sequence reservations in {self.describe()!r}"), \
                self.engine.begin() as conn:
            for thing, seq in reserved.items():
                conn.execute(things.update().where(things.c.key == self.keys[thing]).values(seq_reserved=seq))

    # --- batches ----------------------------------------------------------------------------

    def encode(self, batch: Sequence[Record]) -> list[bytes]:
        return encode_records(batch) if self.compact else [r.data.encode() for r in batch]

    def prepare(self, batch: Sequence[Record], payloads: list[bytes] | None = None) -> Prepared:
        return Prepared(self._rows(batch, self.encode(batch) if payloads is None else payloads))

    def _rows(self, batch: Sequence[Record], payloads: list[bytes]) -> list[Row]:
        keys = self.keys
        try:
            return [(keys[r.thing], r.seq, r.t_ns, r.kind, r.name, d)
                    for r, d in zip(batch, payloads, strict=True)]
        except KeyError as e:
            raise RecordRefused(f"Thing {e.args[0]!r} was never registered with the history writer") \
                from None

    def write(self, batch: Prepared, reserve: Mapping[str, int], meanwhile: Step | None = None) -> None:
        things = ThingRow.__table__
        keys = self.keys
        with translated(), self.engine.begin() as conn:
            self._insert(conn, batch, meanwhile)
            for thing, reserved in reserve.items():
                conn.execute(things.update().where(things.c.key == keys[thing]).values(seq_reserved=reserved))

    def _insert(self, conn: sa.Connection, batch: Prepared, meanwhile: Step | None) -> None:
        table = EventRow.__tablename__
        rows = batch.rows
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
                raise RecordRefused(f"a value out of range: {e}") from None

    # --- the database as a whole ------------------------------------------------------------

    def check_integrity(self) -> None:
        """Other engines check their own storage: nothing to do."""

    def apply_retention(self, retention: Retention) -> int:
        with translated():
            return apply_retention(self.engine, retention)
