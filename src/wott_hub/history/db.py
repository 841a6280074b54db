"""Open the history database and bring its schema up to date.

A plain path means SQLite; anything with ``://`` is an SQLAlchemy URL (e.g.
``postgresql+psycopg://user@host/db``). SQLite runs in WAL mode with
``synchronous=NORMAL``: readers (SSE resume, export) never block the writer,
and a committed transaction survives a crash of the hub process (SIGKILL);
only a power loss can take back the last commits.
"""

from __future__ import annotations

import logging
from functools import cache
from pathlib import Path

import sqlalchemy as sa
from sqlalchemy.engine import Engine

__all__ = ["HistoryError", "create_engine", "current_revision", "database_url", "migrations_dir", "upgrade"]

log = logging.getLogger(__name__)


class HistoryError(RuntimeError):
    """The history database cannot be opened or upgraded."""


def database_url(value: str | Path) -> str:
    """An SQLAlchemy URL from a config value: a file path or a URL."""
    text = str(value)
    if "://" in text:
        return text
    return f"sqlite:///{Path(text).expanduser().resolve()}"


def _sqlite_pragmas(dbapi_conn, _record) -> None:
    cur = dbapi_conn.cursor()
    cur.execute("PRAGMA journal_mode=WAL")
    cur.execute("PRAGMA synchronous=NORMAL")
    cur.execute("PRAGMA busy_timeout=10000")
    cur.execute("PRAGMA cache_size=-32000")  # 32 MB page cache: replay/export read sequentially
    cur.close()


def create_engine(url: str) -> Engine:
    engine = sa.create_engine(url, future=True, pool_pre_ping=not url.startswith("sqlite"))
    if engine.dialect.name == "sqlite":
        if url.startswith("sqlite:///") and url != "sqlite:///:memory:":
            Path(url.removeprefix("sqlite:///")).parent.mkdir(parents=True, exist_ok=True)
        sa.event.listen(engine, "connect", _sqlite_pragmas)
    return engine


@cache
def migrations_dir() -> Path:
    """``migrations/`` of the source tree, or the copy packaged inside the wheel."""
    here = Path(__file__).resolve()
    for candidate in (here.parents[3] / "migrations", here.parents[1] / "_migrations"):
        if (candidate / "env.py").exists():
            return candidate
    raise HistoryError("the history migrations (migrations/env.py) are not installed")


def _alembic_config():
    from alembic.config import Config

    cfg = Config()
    cfg.set_main_option("script_location", str(migrations_dir()))
    return cfg


def current_revision(engine: Engine) -> str | None:
    """The database's Alembic revision, read without Alembic; None for an empty database."""
    try:
        with engine.connect() as conn:
            return conn.exec_driver_sql("SELECT version_num FROM alembic_version").scalar()
    except sa.exc.DBAPIError:
        return None


def upgrade(engine: Engine) -> str:
    """Upgrade the schema to the newest revision; returns it. Cheap when already there."""
    from .models import HEAD_REVISION

    if current_revision(engine) == HEAD_REVISION:
        return HEAD_REVISION
    from alembic import command
    from alembic.runtime.migration import MigrationContext
    from alembic.script import ScriptDirectory

    cfg = _alembic_config()
    head = ScriptDirectory.from_config(cfg).get_current_head()
    try:
        with engine.connect() as conn:
            current = MigrationContext.configure(conn).get_current_revision()
            if current == head:
                return head
            log.info("upgrading history database from %s to %s", current, head)
            cfg.attributes["connection"] = conn
            command.upgrade(cfg, "head")
            conn.commit()
    except sa.exc.SQLAlchemyError as e:
        raise HistoryError(f"cannot open or upgrade the history database {engine.url!r}: {e}") from e
    return head
