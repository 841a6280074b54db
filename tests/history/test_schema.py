"""The SQLAlchemy models and the Alembic migrations describe the same schema."""

from __future__ import annotations

import sqlalchemy as sa
from alembic.autogenerate import compare_metadata
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory

from wott_hub.history import Base, create_engine, database_url, upgrade
from wott_hub.history.db import current_revision, migrations_dir
from wott_hub.history.models import HEAD_REVISION


def test_migrations_match_models(tmp_path):
    engine = create_engine(database_url(tmp_path / "h.db"))
    assert upgrade(engine) == HEAD_REVISION
    with engine.connect() as conn:
        diff = compare_metadata(MigrationContext.configure(conn), Base.metadata)
    assert diff == []


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
    assert {"things", "events", "alembic_version"} <= tables


def test_events_are_appended_to_the_rowid_and_unique_per_thing_and_seq(tmp_path):
    engine = create_engine(database_url(tmp_path / "h.db"))
    upgrade(engine)
    with engine.connect() as conn:
        sql = conn.exec_driver_sql("SELECT sql FROM sqlite_master WHERE name = 'events'").scalar()
    assert "id INTEGER NOT NULL" in sql and "PRIMARY KEY (id)" in sql  # the rowid: append-only inserts
    assert "UNIQUE (thing_key, seq)" in sql
