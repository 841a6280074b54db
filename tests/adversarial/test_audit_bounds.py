"""Issue 33, item 3: clients without a token cannot grow the database or the log, nor erase history.

A real hub with tokens (enforced on loopback), a device recording. The attack of the issue:
600 x ``GET /wot/<60,000 x a>`` without a token. Before, each refusal was an audit row holding the whole
path (+38 MB), never trimmed, while ``retention_mb`` counted its pages and deleted devices' events to
make room (33,000 -> 1,500 events per pass); two log lines per request held the path (72 MB of log).
Measured here: the log's bytes during the flood, the audit trail's rows and bytes (every request still
counted), what a retention pass sized for the events alone deletes after the flood (nothing), and the
same with 600 distinct paths. Also: the audit trail trimmed by age and to its row cap like events, and
migration 0007 (``count``, ``last_ns``) up and down on SQLite and PostgreSQL.
"""

from __future__ import annotations

import logging
import uuid

import httpx
import pytest
import sqlalchemy as sa
from alembic import command

from wott_hub.config import HubConfig
from wott_hub.history import Retention, apply_retention, create_engine, database_url, upgrade
from wott_hub.history.db import _alembic_config
from wott_hub.history.models import HEAD_REVISION
from wott_hub.history.retention import used_bytes
from wott_hub.network import DirectoryConfig
from wott_hub.security import TokenFile, read_audit
from wott_hub.security.config import SecurityConfig
from wott_hub.security.scopes import Scope


class _Bytes(logging.Handler):
    """What the hub's log would hold at the default level (warning): bytes of formatted lines."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
        self.total = 0

    def emit(self, record: logging.LogRecord) -> None:
        self.total += len(self.format(record)) + 1


@pytest.fixture
def hub(tmp_path, hub_thread, press_scene, eventually):
    tokens = tmp_path / "tokens.json"
    TokenFile(tokens).create("reader", Scope.READ)
    cfg = HubConfig(http_port=0, ws_port=0, database=str(tmp_path / "hub.db"),
                    devices=(press_scene("pad"),), directory=DirectoryConfig(enabled=False),
                    security=SecurityConfig(tokens_file=str(tokens)))
    ht = hub_thread(cfg).start()
    eventually(lambda: ht.hub.flush_history(1) and ht.hub._history.writer.committed.get("pad", 0) > 200, 60,
               "pad recorded")
    yield ht
    ht.stop()


def _events(engine) -> int:
    with engine.connect() as conn:
        return conn.execute(sa.text("SELECT count(*) FROM events")).scalar_one()


def _audit(engine) -> tuple[int, int, int, int]:
    """Rows, requests counted, bytes of targets, the longest target (a row is one request in a database
    without ``count``: before revision 0007)."""
    with engine.connect() as conn:
        columns = {c["name"] for c in sa.inspect(conn).get_columns("audit_log")}
        requests = "coalesce(sum(count), 0)" if "count" in columns else "count(*)"
        return tuple(conn.execute(sa.text(
            f"SELECT count(*), {requests}, coalesce(sum(length(target)), 0), "
            "coalesce(max(length(target)), 0) FROM audit_log WHERE status = 401")).one())


def test_a_flood_of_refused_long_paths_grows_neither_the_log_nor_the_database_nor_erases_history(
        hub, tmp_path, eventually):
    max_target = 256  # audit.MAX_TARGET
    engine = create_engine(database_url(tmp_path / "hub.db"))
    logs = _Bytes()
    logging.getLogger().addHandler(logs)
    try:
        with engine.connect() as conn:
            before = used_bytes(conn)
        assert before is not None
        events_before = _events(engine)
        with httpx.Client(timeout=30) as client:
            for _ in range(600):
                r = client.get(f"{hub.url}/wot/{'a' * 60_000}")
                assert r.status_code == 401
        logged = logs.total
        rows, requests, text, longest = eventually(lambda: (a := _audit(engine))[1] == 600 and a, 30,
                                                   lambda: f"the 600 refusals audited: {_audit(engine)}")
        events = _events(engine)
        # room for twice the events, those the device added during the flood included (a loaded machine
        # makes the flood last longer), no more: the audit rows must not need any of it
        limit_mb = 2 * before * max(1.0, events / events_before) / 1e6
        deleted = apply_retention(engine, Retention(max_mb=limit_mb))  # a pass sized for the events
        after = _events(engine)
    finally:
        logging.getLogger().removeHandler(logs)
        engine.dispose()
    assert logged < 100_000, f"the flood wrote {logged} bytes of log"  # before: ~72 MB
    assert rows <= 3 and longest <= max_target and text <= 3 * max_target, (rows, longest, text)
    assert deleted == 0 and after >= events, f"retention deleted {deleted} events ({events} -> {after})"


def test_a_flood_of_distinct_paths_is_capped_per_address_and_still_counted(hub, tmp_path, eventually):
    from wott_hub.security.audit import MAX_TARGET, MAX_TARGETS_PER_MINUTE

    engine = create_engine(database_url(tmp_path / "hub.db"))
    try:
        with httpx.Client(timeout=30) as client:
            for _ in range(600):
                assert client.get(f"{hub.url}/wot/{uuid.uuid4().hex * 30}").status_code == 401
        rows, requests, text, longest = eventually(lambda: (a := _audit(engine))[1] == 600 and a, 30,
                                                   lambda: f"the 600 refusals audited: {_audit(engine)}")
    finally:
        engine.dispose()
    # a minute boundary in the middle of the flood gives the address its share twice, at most
    assert rows <= 2 * (MAX_TARGETS_PER_MINUTE + 1), rows
    assert longest <= MAX_TARGET


def test_the_audit_trail_is_trimmed_by_age_and_to_its_row_cap(tmp_path, monkeypatch):
    from wott_hub.history import retention
    from wott_hub.history.retention import trim_audit

    engine = create_engine(database_url(tmp_path / "h.db"))
    upgrade(engine)
    day = 86_400 * 10**9
    now = 1_800_000_000 * 10**9
    with engine.begin() as conn:
        conn.execute(sa.text("INSERT INTO audit_log (t_ns, who, action, target, address, status) "
                             "VALUES (:t, '-', 'GET', '/x', '10.0.0.1', 401)"),
                     [{"t": now - (3 - i // 50) * day} for i in range(150)])  # 50 each 3, 2 and 1 days old
    assert trim_audit(engine, Retention(days=2.5), now) == 50  # by age, as events
    monkeypatch.setattr(retention, "AUDIT_MAX_ROWS", 60)
    assert trim_audit(engine, Retention(), now) == 40  # retention off: the cap still holds
    entries = read_audit(engine, limit=1000)
    assert len(entries) == 60 and sum(e.t_ns == now - day for e in entries) == 50  # the newest kept
    engine.dispose()


@pytest.mark.parametrize("dialect", ["sqlite", "postgresql"])
def test_migration_0007_adds_counts_to_existing_rows_and_goes_back(dialect, tmp_path, request):
    url = database_url(tmp_path / "h.db") if dialect == "sqlite" else request.getfixturevalue("pg_url")
    engine = create_engine(url)
    cfg = _alembic_config()
    try:
        with engine.begin() as conn:
            cfg.attributes["connection"] = conn
            command.upgrade(cfg, "0006")
            conn.execute(sa.text("INSERT INTO audit_log (t_ns, who, action, target, address, status) "
                                 "VALUES (1, 'r', 'POST', '/wot/hub/actions/replay', '127.0.0.1', 200)"))
        assert upgrade(engine) == HEAD_REVISION == "0007"
        (entry,) = read_audit(engine)
        assert (entry.count, entry.last_ns, entry.target) == (1, None, "/wot/hub/actions/replay")
        with engine.begin() as conn:
            cfg.attributes["connection"] = conn
            command.downgrade(cfg, "0006")
        with engine.connect() as conn:
            columns = {c["name"] for c in sa.inspect(conn).get_columns("audit_log")}
        assert "count" not in columns and "last_ns" not in columns
        assert upgrade(engine) == "0007"
    finally:
        engine.dispose()
