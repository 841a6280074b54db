"""The storage engine of a database, chosen by its SQLAlchemy dialect.

Like rosbag2's storage factory: the writer and its batch process ask here for the
``StorageWriter`` of a database and never name an engine themselves.
"""

from __future__ import annotations

from sqlalchemy.engine import Engine

from .lease import DEFAULT_HUB_ID, LEASE_STALE_S
from .postgres import PostgresStorage
from .sql import SqlStorage
from .sqlite import SqliteStorage
from .storage import StorageWriter

__all__ = ["open_storage"]


def open_storage(engine: Engine, *, compact: bool = True, hub_id: str = DEFAULT_HUB_ID,
                 lease_stale_s: float = LEASE_STALE_S) -> StorageWriter:
    """``engine``'s storage: SQLite's, PostgreSQL's, or the portable one for another dialect."""
    kind = {"sqlite": SqliteStorage, "postgresql": PostgresStorage}.get(engine.dialect.name, SqlStorage)
    return kind(engine, compact=compact, hub_id=hub_id, lease_stale_s=lease_stale_s)
