"""The directory's tables, on their own MetaData so ``create_all`` touches nothing else.

Table names start with ``tdd_`` so they can live in the hub's database. The TD
is stored as JSON text in the enriched form the directory serves (with its
``registration`` block); the timestamp columns repeat what the TD says, for
queries and inspection outside the directory. The directory itself never asks
SQL for expired rows: it rebuilds the expiry times from the stored TDs at start
and purges from an in-memory heap (``Directory.purge``).
"""

from __future__ import annotations

from datetime import datetime

from sqlalchemy import BigInteger, Boolean, DateTime, Index, MetaData, String, Text
from sqlalchemy.engine import Engine
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

__all__ = ["Base", "EventRow", "ThingRow", "create_schema"]


class Base(DeclarativeBase):
    metadata = MetaData()


class ThingRow(Base):
    __tablename__ = "tdd_things"

    id: Mapped[str] = mapped_column(String(2048), primary_key=True)
    td: Mapped[str] = mapped_column(Text)
    anonymous: Mapped[bool] = mapped_column(Boolean, default=False)
    own: Mapped[bool] = mapped_column(Boolean, default=False)
    """The directory's own TD (replaced, not kept, when its base URL changes)."""
    created: Mapped[datetime] = mapped_column(DateTime(timezone=True))
    modified: Mapped[datetime] = mapped_column(DateTime(timezone=True))
    expires: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)

    __table_args__ = (Index("ix_tdd_things_expires", "expires"),)


class EventRow(Base):
    """One lifecycle event; ``data`` is the full TD (created) or the merge patch (updated)."""

    __tablename__ = "tdd_events"

    id: Mapped[int] = mapped_column(BigInteger, primary_key=True, autoincrement=False)
    type: Mapped[str] = mapped_column(String(16))
    thing_id: Mapped[str] = mapped_column(String(2048))
    created: Mapped[datetime] = mapped_column(DateTime(timezone=True))
    data: Mapped[str | None] = mapped_column(Text, nullable=True)


def create_schema(engine: Engine) -> None:
    """Create the directory's tables if missing (standalone; the hub creates them with its Alembic
    migrations, revision 0002, and opens the directory with ``create_tables=False``)."""
    Base.metadata.create_all(engine)
