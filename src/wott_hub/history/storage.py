"""The storage interfaces: what the history writer needs of a database, and what play and export read.

As rosbag2 keeps its storage interfaces (``rosbag2_storage``) below its writer and its record
and play (``rosbag2_cpp``, ``rosbag2_transport``): the writer (``writer.py``: queue, thread,
isolation of refused rows, watermarks, reservations, health) and play and export
(``replay.py``, ``merge.py``, ``export.py``, ``mcap.py``) are written against these protocols;
the engines behind them (``sql.py``, the portable one, ``sqlite.py`` and ``postgres.py``, chosen
by the database's dialect in ``engines.py``) know the SQL, the driver and its fastest bulk path.
Every engine stores the one schema of ``models.py`` (the migrations make it), so a batch in an
engine's hands is a list of the events table's rows.

Contract of a ``StorageWriter``:
- ``register`` creates or updates a Thing's row and, in the same transaction, reserves its
  sequence ``ahead`` of the last seq that may have been used, which it returns; ``Conflict`` if
  a live hub of another id records that Thing. The writer holds the ``lease`` before the first.
- ``write`` writes a prepared batch and moves the reservations of ``reserve`` (Thing -> seq) in
  one transaction: all of it or nothing. ``RecordRefused`` when the database refused rows for
  their data (the writer halves the batch to find them); any other error is a ``HistoryError``
  (the writer retries). Errors are the tree's (``db_errors.py``), never SQLAlchemy's.
- ``encode`` (the stored payloads, ``codec.py``) and ``prepare`` (the rows; ``RecordRefused``
  for a Thing never registered) make a batch ready apart from writing it: an engine that
  ``overlaps`` runs ``write``'s ``meanwhile`` steps while the database takes the data, and the
  writer prepares its next batch in them.
- ``release`` sets the reservations back to what was committed (a clean stop: no gap).
- ``known`` (is the Thing in the database? its key then in ``keys``) and ``recorded`` (which seqs
  of a range it has) let the writer forward its spool (``spool.py``) without duplicates, the
  Things of a previous run included.

A ``StorageReader`` raises ``HistoryError`` for a read the database fails (and notes it in the
database's ``state``), never an empty answer; it gives records back as ``Record``s, each payload
the exact text sent live.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from itertools import repeat
from typing import TYPE_CHECKING, Any, NamedTuple, Protocol

from wott_hub.events.record import Record

if TYPE_CHECKING:
    from .lease import Lease
    from .retention import Retention
    from .state import DatabaseState

__all__ = ["Columns", "Prepared", "Row", "Step", "StorageReader", "StorageWriter", "ThingSummary"]

Step = Callable[[], bool]
"""One step of work done while the database takes a batch; False once nothing is left."""

Row = tuple[int, int, int, int, str, bytes]
"""A record as the events table holds it: (thing_key, seq, t_ns, kind, name, data)."""


class Prepared(NamedTuple):
    """A batch ready to write: its rows, and the bytes the engine sends them as if it builds them
    ahead (PostgreSQL: binary COPY data), else None."""

    rows: list[Row]
    wire: bytearray | None = None


class StorageWriter(Protocol):
    url: str
    """The database's URL, password included: what a batch process opens (never shown)."""
    keys: dict[str, int]
    """Each registered Thing's key in the database (a batch process is told the ones it writes)."""
    lease: Lease
    state: DatabaseState
    overlaps: bool

    def register(self, thing: str, *, title: str, family: str, td: str | None, static_values: str | None,
                 ahead: int) -> int: ...

    def encode(self, batch: Sequence[Record]) -> list[bytes]: ...

    def prepare(self, batch: Sequence[Record], payloads: list[bytes] | None = None) -> Prepared: ...

    def write(self, batch: Prepared, reserve: Mapping[str, int], meanwhile: Step | None = None) -> None: ...

    def release(self, reserved: Mapping[str, int]) -> None: ...

    def known(self, thing: str) -> bool: ...

    def recorded(self, thing: str, lo: int, hi: int) -> set[int]: ...

    def check_integrity(self) -> None: ...

    def apply_retention(self, retention: Retention) -> int: ...


@dataclass(frozen=True)
class ThingSummary:
    id: str
    title: str
    family: str
    count: int | None  # None: not counted (``StorageReader.things(count=False)``)
    first_seq: int | None
    last_seq: int | None
    first_t_ns: int | None
    last_t_ns: int | None

    def to_dict(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


class Columns(NamedTuple):
    """A page of one Thing's records as columns, payloads decoded: how a reader reads a page before
    it makes ``Record``s of it, and what a replay of one Thing walks, making a ``Record`` only as it
    emits one. (A page of 20,000 ``Record``s made at once costs ~0.2 µs more a record than the same
    made one by one and let go: the garbage collector's passes over the live ones, measured.)"""

    seqs: Sequence[int]
    times: Sequence[int]
    kinds: Sequence[int]
    names: Sequence[str]
    data: list[str]

    def records(self, thing: str) -> list[Record]:
        return list(map(Record, repeat(thing), self.seqs, self.kinds, self.names, self.times, self.data))


class StorageReader(Protocol):
    @property
    def failure(self) -> str:
        """Why this database cannot be trusted to answer (known corrupted), else ""."""
        ...

    def things(self, *, count: bool = True) -> list[ThingSummary]:
        """Every recorded Thing, its first and last seq and time; ``count``: its exact number of
        records too (the one part that reads more than an index's ends)."""
        ...

    def thing_info(self, thing: str) -> dict[str, Any] | None:
        """Title, family, TD and static property values recorded for ``thing``."""
        ...

    def recorded(self, thing: str) -> bool: ...

    def first_time(self, things: Sequence[str], t_from_ns: int | None) -> int | None:
        """The earliest record time of any of ``things`` at or after ``t_from_ns``."""
        ...

    def pages(self, thing: str, t_from_ns: int | None = None, t_to_ns: int | None = None,
              names: list[str] | None = None, page: int = 20_000, *,
              numbers: bool = False) -> Iterator[list[Record]]:
        """``thing``'s records in [t_from, t_to] (only ``names``, if given) in seq (= time) order;
        ``numbers``: packed skin and displacement packets as records carrying their numbers, their
        text written only if read (``history/numbers.py``; the same records otherwise)."""
        ...

    def columns(self, thing: str, t_from_ns: int | None = None, t_to_ns: int | None = None,
                names: list[str] | None = None, page: int = 20_000) -> Iterator[Columns]:
        """``pages`` as ``Columns`` (no page empty)."""
        ...

    def record_page(self, thing: str, *, t_from_ns: int | None = None, t_to_ns: int | None = None,
                    names: list[str] | None = None, after: int = 0, limit: int = 1000) -> list[Record]:
        """Up to ``limit`` of those records with seq > ``after``; ``NotFound`` for a Thing never recorded."""
        ...

    def last_at(self, thing: str, name: str, t_ns: int, limit: int = 1) -> list[Record]:
        """The ``limit`` latest records of ``name`` at or before ``t_ns``, latest first (a zero-order
        hold's value at ``t_ns``)."""
        ...
