"""Open the history database and bring its schema up to date.

A plain path means SQLite; anything with ``://`` is an SQLAlchemy URL (e.g.
``postgresql+psycopg://user@host/db``; a bare ``postgresql://`` means the same, psycopg 3
being the driver installed with wott-hub; docs/postgres.md). SQLite runs in WAL mode with
``synchronous=NORMAL``: readers (SSE resume, export) never block the writer,
and a committed transaction survives a crash of the hub process (SIGKILL);
only a power loss can take back the last commits.

Contract: everything that goes wrong opening a database (an unknown URL scheme,
a missing driver, a schema newer than this wott-hub, a file that is not a
history database, a corrupted one) is a ``wott_hub.errors.HistoryError`` whose
message names the database: one line on the CLI, health "degraded" in a hub.
"""

from __future__ import annotations

import logging
import os
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

import sqlalchemy as sa
from sqlalchemy.engine import Engine

from wott_hub.errors import HistoryError

from .db_errors import database_error, translated

if TYPE_CHECKING:
    from alembic.config import Config

__all__ = ["CONNECT_TIMEOUT_S", "check_integrity", "create_engine", "current_revision", "database_url",
           "describe", "migrations_dir", "open_existing", "upgrade"]

log = logging.getLogger(__name__)

_SQLITE_MAGIC = b"SQLite format 3\x00"
_MIGRATION_LOCK = 0x776F7474  # "wott": the PostgreSQL advisory lock key held while migrating


def database_url(value: str | Path) -> str:
    """An SQLAlchemy URL from a config value: a file path or a URL."""
    text = str(value)
    for bare in ("postgresql://", "postgres://"):  # psycopg 3 is the driver installed with wott-hub
        if text.startswith(bare):
            return "postgresql+psycopg://" + text.removeprefix(bare)
    if "://" in text:
        return text
    return f"sqlite:///{Path(text).expanduser().resolve()}"


def _sqlite_pragmas(dbapi_conn: Any, _record: Any) -> None:
    cur = dbapi_conn.cursor()
    # before any table exists, so that a new file is made with it: freed pages can then be given
    # back to the file system (retention.py); an existing file gets it in migration 0006 (VACUUM)
    cur.execute("PRAGMA auto_vacuum=INCREMENTAL")
    cur.execute("PRAGMA journal_mode=WAL")
    cur.execute("PRAGMA synchronous=NORMAL")
    cur.execute("PRAGMA busy_timeout=10000")
    cur.execute("PRAGMA cache_size=-32000")  # 32 MB page cache: replay/export read sequentially
    # a batch's multi-row INSERT keeps a statement journal (to undo that statement alone): in a
    # temporary file made and deleted per statement (~45 a second at 32 devices, strace); in memory
    cur.execute("PRAGMA temp_store=MEMORY")
    cur.close()


def describe(url: str | sa.URL) -> str:
    """The database as a person would name it: the file of an SQLite URL, else the URL without
    its password."""
    text = str(url)
    if text.startswith("sqlite:///"):
        return text.removeprefix("sqlite:///")
    try:
        return sa.make_url(text).render_as_string(hide_password=True)
    except sa.exc.ArgumentError:
        return text


CONNECT_TIMEOUT_S = 5
"""A PostgreSQL server that does not answer (a host gone, packets dropped) fails a connection after
this long instead of the system's TCP timeout (minutes): the writer then spools and a stop stays
bounded. A URL's own ``connect_timeout`` wins."""


def create_engine(url: str) -> Engine:
    """An engine on ``url``; an unknown scheme or a driver that is not installed is a HistoryError."""
    args: dict[str, Any] = {}
    if url.startswith("postgresql") and "connect_timeout" not in url:
        args["connect_timeout"] = CONNECT_TIMEOUT_S
    try:
        engine = sa.create_engine(url, future=True, pool_pre_ping=not url.startswith("sqlite"),
                                  connect_args=args)
    except (sa.exc.ArgumentError, ImportError) as e:  # NoSuchModuleError is an ArgumentError
        raise HistoryError(f"cannot use the history database {describe(url)!r}: {e} (a file path, or a "
                           "URL such as postgresql+psycopg://user@host/db)") from None
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


def _alembic_config() -> Config:
    from alembic.config import Config

    cfg = Config()
    cfg.set_main_option("script_location", str(migrations_dir()))
    return cfg


def current_revision(engine: Engine) -> str | None:
    """The database's Alembic revision, read without Alembic; None for an empty database."""
    try:
        with engine.connect() as conn:
            return conn.exec_driver_sql("SELECT version_num FROM alembic_version").scalar()
    except sa.exc.OperationalError as e:
        if "no such table" in str(e) or "does not exist" in str(e):
            return None
        raise database_error(e, f"cannot read the history database {describe(engine.url)!r}") from None
    except sa.exc.ProgrammingError:  # PostgreSQL: relation "alembic_version" does not exist
        return None
    except sa.exc.DBAPIError as e:  # not a database, corrupted, unreachable
        raise database_error(e, f"cannot read the history database {describe(engine.url)!r}") from None


def _known_revisions() -> tuple[list[str], str]:
    """Every revision of ``migrations/versions`` and the head (imports Alembic: ~0.5 s)."""
    from alembic.script import ScriptDirectory

    script = ScriptDirectory.from_config(_alembic_config())
    return [rev.revision for rev in script.walk_revisions()], script.get_current_head() or ""


def _check_known(engine: Engine, current: str | None) -> str:
    """``current`` if this wott-hub knows it (head or older), else a HistoryError."""
    known, head = _known_revisions()
    if current is not None and current not in known:
        raise HistoryError(f"the history database {describe(engine.url)!r} has schema revision {current!r}, "
                           f"which this wott-hub does not know (its newest is {head!r}): it was written "
                           "by a newer wott-hub; upgrade wott-hub to use it")
    return head


def upgrade(engine: Engine) -> str:
    """Upgrade the schema to the newest revision; returns it. Cheap when already there.

    A schema newer than this wott-hub knows is refused (never downgraded, never
    half-migrated); so is a file that is not an SQLite database."""
    from .models import HEAD_REVISION

    _check_sqlite_file(engine, allow_empty=True)
    current = current_revision(engine)
    if current == HEAD_REVISION:
        return HEAD_REVISION
    head = _check_known(engine, current)
    from alembic import command
    from alembic.runtime.migration import MigrationContext

    cfg = _alembic_config()
    try:
        with engine.connect() as conn:
            if conn.dialect.name == "postgresql":
                # hubs of a fleet starting together on one database: one migrates, the others
                # wait here and then find it at head (released with the transaction)
                conn.exec_driver_sql(f"SELECT pg_advisory_xact_lock({_MIGRATION_LOCK})")
            current = MigrationContext.configure(conn).get_current_revision()
            if current == head:
                conn.commit()
                return head
            log.info("upgrading history database from %s to %s", current, head)
            cfg.attributes["connection"] = conn
            command.upgrade(cfg, "head")
            conn.commit()
    except sa.exc.SQLAlchemyError as e:
        raise database_error(e, f"cannot open or upgrade the history database {describe(engine.url)!r}") \
            from None
    except Exception as e:  # Alembic's own errors (CommandError, ...): one line, not a traceback
        if isinstance(e, HistoryError):
            raise
        raise HistoryError(f"cannot upgrade the history database {describe(engine.url)!r}: {e}") from None
    return head


def _sqlite_file(engine: Engine) -> Path | None:
    url = str(engine.url)
    if engine.dialect.name != "sqlite" or not url.startswith("sqlite:///") or url == "sqlite:///:memory:":
        return None
    return Path(url.removeprefix("sqlite:///"))


SIDECARS = {"-wal": "write-ahead log", "-shm": "shared-memory index", "-journal": "rollback journal"}
"""The files SQLite opens itself beside a database ``<db><suffix>``, and what each is."""


def check_sidecars(path: Path) -> None:
    """Each of SQLite's own files beside ``path`` is a regular file or absent: SQLite opens them itself,
    so a FIFO there blocked its open for ever (SIGTERM ignored) and ``/dev/zero`` would be mapped or read
    without end (issue 48). A symlink to a regular file is followed as SQLite does; a dangling one is
    refused (SQLite would create its target wherever it points)."""
    for suffix, what in SIDECARS.items():
        side = path.with_name(path.name + suffix)
        if os.path.lexists(side) and not side.is_file():
            raise HistoryError(f"{str(side)!r} is not a regular file: it would be SQLite's {what} of the "
                               "history database beside it; remove it")


def _check_sqlite_file(engine: Engine, *, allow_empty: bool) -> None:
    """An existing SQLite file must start with SQLite's header (else it is not a database at all); the
    files SQLite opens beside it must be regular files (``check_sidecars``), whether it exists or not."""
    path = _sqlite_file(engine)
    if path is None:
        return
    check_sidecars(path)
    if not path.exists():
        return
    if not path.is_file():  # a FIFO would block the open below and SQLite's; a device never ends
        raise HistoryError(f"{str(path)!r} is not a regular file: not a wott-hub history database")
    try:
        with path.open("rb") as f:
            head = f.read(len(_SQLITE_MAGIC))
    except OSError as e:
        raise HistoryError(f"cannot read the history database {str(path)!r}: {e}") from None
    if not head and allow_empty:
        return
    if head != _SQLITE_MAGIC:
        what = "is empty" if not head else "is not an SQLite database"
        raise HistoryError(f"{str(path)!r} {what}: not a wott-hub history database")


def check_integrity(engine: Engine) -> None:
    """SQLite's ``PRAGMA quick_check`` (every page and index readable and consistent; a full
    scan, ~1 s per GB); a HistoryError naming the first problem. Other engines check their own
    storage: nothing to do."""
    if engine.dialect.name != "sqlite":
        return
    with translated(f"the history database {describe(engine.url)!r} is corrupted"), engine.connect() as conn:
        result = conn.exec_driver_sql("PRAGMA quick_check(1)").scalar()
    if result != "ok":
        problem = "; ".join(line for line in str(result).splitlines() if not line.startswith("***"))
        raise HistoryError(f"the history database {describe(engine.url)!r} is corrupted: {problem}")


def open_existing(database: str | Path, *, integrity: bool = True) -> Engine:
    """An engine on an existing history database, for reading (``history``, ``replay``): never
    creates a file, never migrates; a HistoryError if it is missing, empty, not a history
    database, of a newer schema, or (``integrity``) corrupted."""
    url = database_url(database)
    path = Path(url.removeprefix("sqlite:///")) if url.startswith("sqlite:///") else None
    if path is not None and not path.is_file():
        raise HistoryError(f"no history database at {str(path)!r}")
    engine = create_engine(url)
    try:
        _check_sqlite_file(engine, allow_empty=False)
        from .models import HEAD_REVISION

        current = current_revision(engine)
        if current is None:
            raise HistoryError(f"{describe(engine.url)!r} is not a wott-hub history database (no schema)")
        if current != HEAD_REVISION:
            _check_known(engine, current)
        if integrity:
            check_integrity(engine)
    except BaseException:
        engine.dispose()
        raise
    return engine
