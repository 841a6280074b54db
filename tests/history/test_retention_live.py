"""Retention on a running hub: records past ``retention_days`` and over ``retention_mb`` disappear
while the hub keeps recording, and the SQLite file stops growing (incremental auto-vacuum)."""

from __future__ import annotations

import asyncio
import os
import time

import sqlalchemy as sa

from wott_hub.config import HubConfig
from wott_hub.history import HistoryWriter, create_engine, database_url, upgrade
from wott_hub.history.retention import Retention, RetentionClock, used_bytes

from .skin_records import busy_scene, register_device, skin_records

LIMIT_MB = 0.6  # a few seconds of the two busy devices (their skin packets and, since issue 29, vectors)


def _old_recording(path: str) -> int:
    """A device recorded three days ago, in the database before the hub starts."""
    engine = create_engine(database_url(path))
    upgrade(engine)
    w = HistoryWriter(engine, interval_s=0.01)
    start, n = register_device(w, "old-dev")
    recs = skin_records("old-dev", start, 400, n, t0_ns=time.time_ns() - 3 * 86_400 * 10**9)
    w.start()
    for r in recs:
        w.submit(r)
    assert w.flush()
    w.stop()
    with engine.connect() as conn:
        assert conn.exec_driver_sql("PRAGMA auto_vacuum").scalar() == 2  # INCREMENTAL, from creation
    engine.dispose()
    return len(recs)


def _counts(engine) -> dict[str, int]:
    with engine.connect() as conn:
        return dict(conn.execute(sa.text(
            "SELECT t.id, count(e.id) FROM things t LEFT JOIN events e ON e.thing_key = t.key "
            "GROUP BY t.id")).all())


def test_old_and_excess_records_go_while_the_hub_writes_and_the_file_stops_growing(tmp_path, hub_thread):
    path = str(tmp_path / "hub.db")
    assert _old_recording(path) == 500
    cfg = HubConfig(http_port=0, ws_port=0, database=path, retention_days=1, retention_mb=LIMIT_MB,
                    devices=(busy_scene("pad"), busy_scene("pad2")))
    ht = hub_thread(cfg).start()
    try:
        writer = ht.hub._history.writer
        # the configured policy, checked every 0.1 s instead of every minute (the test's only change)
        assert writer.retention == Retention(days=1, max_mb=LIMIT_MB)
        writer.retention = Retention(days=1, max_mb=LIMIT_MB, check_every_s=0.1)
        engine = ht.hub._history.engine
        writer._retention_clock = RetentionClock(writer.retention, engine)

        def oldest(thing: str) -> int:
            with engine.connect() as conn:
                return conn.execute(sa.text("SELECT min(seq) FROM events e JOIN things t "
                                            "ON t.key = e.thing_key WHERE t.id = :t"),
                                    {"t": thing}).scalar() or 0

        async def size_limit_reached() -> None:
            while oldest("pad") <= 1 or oldest("pad2") <= 1:  # the first records of both went
                await asyncio.sleep(0.1)

        ht.call(size_limit_reached, timeout=90)
        assert _counts(engine)["old-dev"] == 0  # three days old: past retention_days
        sizes, written = [], []
        for _ in range(16):  # 4 s more of recording, sampled
            time.sleep(0.25)
            sizes.append(os.path.getsize(path))
            written.append(writer.written)
        assert written[-1] > written[0] + 200  # the hub kept recording meanwhile
        with engine.connect() as conn:
            used = used_bytes(conn)
        assert used <= LIMIT_MB * 1e6 * 1.25
        # the file stays at about the limit: it does not keep growing with what was recorded
        assert max(sizes) <= LIMIT_MB * 1e6 * 2, sizes
        assert sizes[-1] <= max(sizes[:8]) + 64 * 1024, sizes
        counts = _counts(engine)
        assert 0 < counts["pad"] < writer.written
        assert writer.health()["state"] == "ok"
    finally:
        ht.stop()
