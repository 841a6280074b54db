"""The database's errors as the hub's (``history/db_errors.py``): refused data is ``RecordRefused``
(never retried), anything else the database says a ``HistoryError`` (retried), with the driver's
message and not SQLAlchemy's statement dump; other errors pass unchanged."""

from __future__ import annotations

import sqlite3

import pytest
import sqlalchemy as sa

from wott_hub.errors import HistoryError, RecordRefused, WottHubError
from wott_hub.history.db_errors import database_error, driver_message, translated


def _fail(engine: sa.Engine, sql: str) -> sa.exc.DBAPIError:
    with engine.begin() as conn, pytest.raises(sa.exc.DBAPIError) as info:
        conn.exec_driver_sql(sql)
    return info.value


@pytest.fixture
def engine():
    eng = sa.create_engine("sqlite://")
    with eng.begin() as conn:
        conn.exec_driver_sql("CREATE TABLE t (k INTEGER PRIMARY KEY)")
        conn.exec_driver_sql("INSERT INTO t VALUES (1)")
    yield eng
    eng.dispose()


def test_refused_data_and_a_failing_database_are_told_apart(engine):
    duplicate = _fail(engine, "INSERT INTO t VALUES (1)")
    missing = _fail(engine, "SELECT * FROM nowhere")
    refused, failed = database_error(duplicate), database_error(missing, "cannot read 'h.db'")
    assert isinstance(refused, RecordRefused) and refused.args[0] == "UNIQUE constraint failed: t.k"
    assert type(failed) is HistoryError and failed.args[0] == "cannot read 'h.db': no such table: nowhere"
    assert "[SQL:" in str(duplicate) and driver_message(duplicate) == "UNIQUE constraint failed: t.k"
    assert isinstance(database_error(sqlite3.IntegrityError("raw cursor")), RecordRefused)
    assert type(database_error(sqlite3.OperationalError("database is locked"))) is HistoryError


def test_translated_leaves_other_errors_alone(engine):
    with pytest.raises(HistoryError, match="^doing: no such table"), translated("doing"), \
            engine.connect() as conn:
        conn.exec_driver_sql("SELECT * FROM nowhere")
    for error in (KeyError("x"), WottHubError("mine")):
        with pytest.raises(type(error)), translated("doing"):
            raise error
