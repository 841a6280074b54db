"""The SQLAlchemy models and the Alembic migrations describe the same schema."""

from __future__ import annotations

import sqlalchemy as sa
from alembic.autogenerate import compare_metadata
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from wott_directory.models import Base as DirectoryBase

from wott_hub.history import Base, create_engine, database_url, upgrade
from wott_hub.history.db import current_revision, migrations_dir
from wott_hub.history.models import HEAD_REVISION


def test_migrations_match_models(tmp_path):
    """The history's models and the embedded directory's (wott_directory.models, tables tdd_*)."""
    engine = create_engine(database_url(tmp_path / "h.db"))
    assert upgrade(engine) == HEAD_REVISION
    with engine.connect() as conn:
        ctx = MigrationContext.configure(conn, opts={"compare_type": True})
        diff = compare_metadata(ctx, [Base.metadata, DirectoryBase.metadata])
    assert diff == []


def test_the_directory_opens_on_the_migrated_database_without_creating_tables(tmp_path):
    import asyncio

    from wott_directory import Directory

    engine = create_engine(database_url(tmp_path / "h.db"))
    bare = Directory(engine=engine, create_tables=False)
    try:  # not migrated: the directory refuses instead of creating its tables behind Alembic's back
        asyncio.run(bare.start())
        raise AssertionError("started without its tables")
    except RuntimeError as e:
        assert "tdd_events, tdd_things are missing" in str(e)
    finally:
        bare.store._executor.shutdown()
    upgrade(engine)

    async def put_and_reload():
        d = Directory(engine=engine, create_tables=False)
        await d.start()
        td = {"@context": "https://www.w3.org/2022/wot/td/v1.1", "id": "urn:ex:lamp", "title": "lamp",
              "securityDefinitions": {"n": {"scheme": "nosec"}}, "security": "n"}
        await d.put("urn:ex:lamp", td)
        await d.stop()
        again = Directory(engine=engine, create_tables=False)
        await again.start()
        try:
            return again.get("urn:ex:lamp")["title"]
        finally:
            await again.stop()

    assert asyncio.run(put_and_reload()) == "lamp"


def test_head_revision_constant_is_the_newest_migration():
    cfg = Config()
    cfg.set_main_option("script_location", str(migrations_dir()))
    assert ScriptDirectory.from_config(cfg).get_current_head() == HEAD_REVISION


def test_upgrade_is_idempotent_and_sqlite_uses_wal(tmp_path):
    engine = create_engine(database_url(tmp_path / "h.db"))
    assert current_revision(engine) is None
    upgrade(engine)
    upgrade(engine)
    assert current_revision(engine) == HEAD_REVISION
    with engine.connect() as conn:
        assert conn.exec_driver_sql("PRAGMA journal_mode").scalar() == "wal"
        assert conn.exec_driver_sql("PRAGMA synchronous").scalar() == 1  # NORMAL
        tables = set(sa.inspect(conn).get_table_names())
    assert {"things", "events", "alembic_version", "tdd_things", "tdd_events"} <= tables


def test_events_are_appended_to_the_rowid_and_unique_per_thing_and_seq(tmp_path):
    engine = create_engine(database_url(tmp_path / "h.db"))
    upgrade(engine)
    with engine.connect() as conn:
        sql = conn.exec_driver_sql("SELECT sql FROM sqlite_master WHERE name = 'events'").scalar()
    assert "id INTEGER NOT NULL" in sql and "PRIMARY KEY (id)" in sql  # the rowid: append-only inserts
    assert "UNIQUE (thing_key, seq)" in sql


def test_the_migration_renders_for_postgresql():
    """The same migration for the scale-out database (offline SQL: no server needed)."""
    import io

    from alembic import command

    cfg = Config(output_buffer=io.StringIO())
    cfg.set_main_option("script_location", str(migrations_dir()))
    cfg.set_main_option("sqlalchemy.url", "postgresql://hub@localhost/wott")
    command.upgrade(cfg, "head", sql=True)
    sql = cfg.output_buffer.getvalue()
    assert "CREATE TABLE events" in sql and "BIGSERIAL" in sql
    assert "UNIQUE (thing_key, seq)" in sql and "CREATE INDEX ix_events_thing_time" in sql


def test_inserts_use_the_drivers_paramstyle():
    from sqlalchemy.dialects import postgresql, sqlite

    from wott_hub.history.sql import positional_insert

    class E:
        def __init__(self, dialect):
            self.dialect = dialect

    cols = ("a", "b")
    assert positional_insert(E(sqlite.dialect()), "t", cols) == "INSERT INTO t (a, b) VALUES (?, ?)"
    two = positional_insert(E(sqlite.dialect()), "t", cols, 2)
    assert two == "INSERT INTO t (a, b) VALUES (?, ?), (?, ?)"
    pg = postgresql.dialect(paramstyle="pyformat")
    assert positional_insert(E(pg), "t", cols, 2) == "INSERT INTO t (a, b) VALUES (%s, %s), (%s, %s)"
    assert positional_insert(E(postgresql.dialect(paramstyle="numeric_dollar")), "t", cols, 2) == (
        "INSERT INTO t (a, b) VALUES ($1, $2), ($3, $4)")
