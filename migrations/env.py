"""Alembic environment of the wott-hub history database.

The hub runs migrations itself at start-up (``wott_hub.history.db.upgrade``),
passing its open connection in ``config.attributes["connection"]``. From the
command line (``uv run alembic upgrade head`` at the repo root) the URL comes
from ``-x url=...``, else ``$WOTT_HUB_DATABASE``, else ``alembic.ini``.
"""

from __future__ import annotations

import os

from alembic import context
from sqlalchemy import create_engine
from wott_directory.models import Base as DirectoryBase

from wott_hub.history.models import Base

config = context.config
# the history's tables and the embedded TD directory's (tdd_*, revision 0002)
target_metadata = [Base.metadata, DirectoryBase.metadata]


def _url() -> str:
    return (context.get_x_argument(as_dictionary=True).get("url")
            or os.environ.get("WOTT_HUB_DATABASE")
            or config.get_main_option("sqlalchemy.url"))


def _migrate(connection) -> None:
    context.configure(
        connection=connection,
        target_metadata=target_metadata,
        render_as_batch=connection.dialect.name == "sqlite",  # SQLite cannot ALTER most things
        compare_type=True,
    )
    with context.begin_transaction():
        context.run_migrations()


def run_offline() -> None:
    context.configure(url=_url(), target_metadata=target_metadata, literal_binds=True)
    with context.begin_transaction():
        context.run_migrations()


def run_online() -> None:
    connection = config.attributes.get("connection")
    if connection is not None:
        _migrate(connection)
        return
    engine = create_engine(_url())
    with engine.connect() as conn:
        _migrate(conn)
    engine.dispose()


if context.is_offline_mode():
    run_offline()
else:
    run_online()
