"""The history schema: one row per recorded Thing, one row per event.

Alembic migrations in ``migrations/`` create exactly this schema (a test
compares them). The same models run on SQLite (the default, one file) and on
PostgreSQL (scale-out), so only portable types are used.

``events`` has a plain integer key (on SQLite the rowid itself): rows are
appended at the end of the table's B-tree, which SQLite does without splitting
pages. (A WITHOUT ROWID table keyed by (thing, seq) measured 4x slower to
write and 3x larger with ~1 kB rows: SQLite half-splits its pages on every
append.) ``uq_events_thing_key`` on (thing, seq) serves resume and ranges;
``ix_events_thing_time`` turns a time range into a seq range. ``data`` holds the
payload sent to subscribers, stored by ``codec.py``: a skinDeformedDetection packet
packed as numbers (~70 B instead of ~700 B of JSON), anything else as its UTF-8 text;
``codec.decode`` gives back the exact text sent live (revision 0006).
"""

from __future__ import annotations

from typing import ClassVar

from sqlalchemy import (
    BigInteger,
    ForeignKey,
    Index,
    Integer,
    LargeBinary,
    MetaData,
    SmallInteger,
    String,
    Table,
    Text,
    UniqueConstraint,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY

__all__ = ["HEAD_REVISION", "KIND_EVENT", "KIND_PROPERTY", "Base", "AuditRow", "EventRow", "HubLeaseRow",
           "ThingRow"]

HEAD_REVISION = "0007"  # 0002: the embedded directory's tables (tdd_things, tdd_events); 0003: hub_lease;
# 0004: audit_log (wott_hub.security.audit); 0005: hub_lease keyed by hub id (one row per hub);
# 0006: events.data as bytes (codec.py: skin packets packed), SQLite auto_vacuum incremental;
# 0007: audit_log.count, last_ns (identical audited requests merged into one row)
"""The newest migration in migrations/versions (a test checks it): a database already
there is opened without importing Alembic, which costs ~0.5 s of start-up."""

# events.kind: KIND_EVENT (an event affordance was emitted) or KIND_PROPERTY (a new value
# of an observable property, e.g. contactInformation)

NAMING = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}


class Base(DeclarativeBase):
    metadata = MetaData(naming_convention=NAMING)
    __table__: ClassVar[Table]  # each model here is one declared table (SQLAlchemy says FromClause)


class ThingRow(Base):
    """A Thing whose events are recorded, with what a replay needs to re-expose it."""

    __tablename__ = "things"

    key: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    id: Mapped[str] = mapped_column(String(200), unique=True)
    title: Mapped[str] = mapped_column(String(200))
    family: Mapped[str] = mapped_column(String(100), default="")
    # The TD (JSON) and static property values (JSON) last served for this Thing
    td: Mapped[str | None] = mapped_column(Text, nullable=True)
    static_values: Mapped[str | None] = mapped_column(Text, nullable=True)
    # Sequence numbers up to this one may have been handed out: a restart after a
    # crash continues above it, so no number a client has seen is ever reused.
    seq_reserved: Mapped[int] = mapped_column(BigInteger, default=0)
    updated_ns: Mapped[int] = mapped_column(BigInteger, default=0)
    # The hub id whose writer records this Thing (lease.py): a hub of another id is refused it
    # while that writer holds its lease (two hubs must never interleave one Thing's sequence).
    hub_id: Mapped[str | None] = mapped_column(String(200), nullable=True)


class EventRow(Base):
    __tablename__ = "events"

    # INTEGER on SQLite, so that it is the rowid (BIGINT PRIMARY KEY would not be)
    id: Mapped[int] = mapped_column(BigInteger().with_variant(Integer(), "sqlite"), primary_key=True,
                                    autoincrement=True)
    thing_key: Mapped[int] = mapped_column(Integer, ForeignKey("things.key", ondelete="CASCADE"))
    seq: Mapped[int] = mapped_column(BigInteger)
    t_ns: Mapped[int] = mapped_column(BigInteger)
    kind: Mapped[int] = mapped_column(SmallInteger)
    name: Mapped[str] = mapped_column(String(100))
    data: Mapped[bytes] = mapped_column(LargeBinary)  # codec.encode / codec.decode

    __table_args__ = (
        UniqueConstraint("thing_key", "seq"),
        Index("ix_events_thing_time", "thing_key", "t_ns"),
    )


class HubLeaseRow(Base):
    """One row per hub identity saying which process writes as that hub (``history/lease.py``).

    The migration inserts the default hub's row (id 1, no holder); a hub with another id
    inserts its own on first use. A writer takes its row with a conditional UPDATE, which
    SQLite and PostgreSQL both apply atomically, so the same code refuses a second process
    of the same hub on either engine while hubs of other ids write side by side.
    """

    __tablename__ = "hub_lease"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    hub_id: Mapped[str] = mapped_column(String(200), unique=True)
    holder: Mapped[str | None] = mapped_column(String(100), nullable=True)
    pid: Mapped[int | None] = mapped_column(Integer, nullable=True)
    host: Mapped[str | None] = mapped_column(String(255), nullable=True)
    acquired_ns: Mapped[int | None] = mapped_column(BigInteger, nullable=True)
    heartbeat_ns: Mapped[int | None] = mapped_column(BigInteger, nullable=True)


class AuditRow(Base):
    """Audited requests (``wott_hub.security.audit``): every write, action and refused credential.
    ``who`` is a token's name (never the token), ``target`` a path without its query, cut to 256
    characters; ``count`` identical requests, the first at ``t_ns``, the last at ``last_ns``."""

    __tablename__ = "audit_log"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    t_ns: Mapped[int] = mapped_column(BigInteger, index=True)
    who: Mapped[str] = mapped_column(String(64))
    action: Mapped[str] = mapped_column(String(16))
    target: Mapped[str] = mapped_column(Text)
    address: Mapped[str] = mapped_column(String(64))
    status: Mapped[int] = mapped_column(Integer)
    count: Mapped[int] = mapped_column(Integer, default=1, server_default="1")
    last_ns: Mapped[int | None] = mapped_column(BigInteger, nullable=True)
