"""Issue 48, items 2, 3 and 5: what lies in the spool folder cannot wedge, flood or silently empty a hub.

Each test runs ``uv run wott-hub run`` (a real SQLite database ``hub.db``, its spool ``hub.db.spool``) with a
file planted in the spool as a local user could, and measures what it did: whether the hub gets ready and
its device streams (events an SSE client reads), the hub's RSS against a hub started on a clean folder,
how long SIGTERM takes, what health and the log say, and what reached history.

- a FIFO named like a segment (``0000000000.seg``), and a FIFO as the spool's ``lock``: before, the hub
  stayed "starting" (blocked opening the FIFO), its devices sent 0 events and SIGTERM was ignored;
- a segment that is a symlink to ``/dev/zero``: before, 7.8 GB in 0.6 s;
- a spool a previous run left (records that could not reach the database: its write lock held) with one
  byte flipped, or its header broken: before, every waiting record was dropped without a word and health
  stayed "ok"; now a flipped byte costs one frame (at most ``FRAME_RECORDS``), named with its count.
"""

from __future__ import annotations

import os
import shutil
import signal
import sqlite3
import textwrap
import time
from pathlib import Path

import httpx
import pytest

from wott_hub.history.spool import FRAME_RECORDS

from . import surroundings as S

STOP_S = 15.0
"""SIGTERM to exit, whatever the spool holds: the bounded stop's seconds (docs/reliability.md)."""


def _config(folder: Path, rate_hz: float = 60.0) -> Path:
    cfg = folder / "hub.toml"
    cfg.write_text(textwrap.dedent("""
        [hub]
        http_port = 0
        ws_port = 0
        database = "hub.db"
    """) + S.press_table("pad", rate_hz))
    return cfg


def _health(url: str) -> dict:
    return httpx.get(f"{url}/properties/health", timeout=10).json()


def _stop(hub) -> float:
    t0 = time.monotonic()
    hub.signal(signal.SIGTERM)
    rc = hub.wait(60)
    took = time.monotonic() - t0
    assert rc is not None, f"the hub still runs 60 s after SIGTERM: {hub.log()[-3000:]}"
    return took


def _run_and_measure(folder: Path, running_hub, sse_ids, eventually) -> dict:
    """Start a hub in ``folder``, read pad's events for a while; its RSS, health, log and stop time."""
    hub = running_hub(["-c", str(_config(folder))], folder)
    try:
        info = hub.ready(60)
        reader = sse_ids(info["devices"]["pad"] + "/events")
        eventually(lambda: len(reader.ids) >= 60, 30, lambda: f"pad streaming: {hub.log()[-2000:]}")
        pid = _hub_pid(hub.proc.pid)
        rss = S.rss_mb(pid)
        health = _health(info["hub"])
        took = _stop(hub)
        reader.stop()
        return {"rss": rss, "health": health, "stop_s": took, "log": hub.log(), "events": len(reader.ids)}
    finally:
        hub.kill()


def _hub_pid(uv_pid: int) -> int:
    """The hub's own process under ``uv run`` (its child), for its RSS."""
    children = [int(p) for task in Path(f"/proc/{uv_pid}/task").iterdir()  # uv forks from any of its threads
                for p in (task / "children").read_text().split()]
    assert children, f"no process under uv ({uv_pid})"
    return children[0]


def _rest_rss(tmp_path: Path, running_hub, sse_ids, eventually) -> float:
    rest = tmp_path / "rest"
    rest.mkdir()
    return _run_and_measure(rest, running_hub, sse_ids, eventually)["rss"]


def test_a_fifo_or_dev_zero_in_the_spool_neither_wedges_nor_floods_the_hub(
        tmp_path, running_hub, sse_ids, eventually):
    rest = _rest_rss(tmp_path, running_hub, sse_ids, eventually)
    for name, plant in (("fifo", lambda sp: S.fifo(sp / "0000000000.seg")),
                        ("fifo-lock", lambda sp: S.fifo(sp / "lock")),
                        ("dev-zero", lambda sp: (sp / "0000000001.seg").symlink_to("/dev/zero"))):
        folder = tmp_path / name
        spool = folder / "hub.db.spool"
        spool.mkdir(parents=True)
        plant(spool)
        got = _run_and_measure(folder, running_hub, sse_ids, eventually)
        print(f"{name}: rss {got['rss']:.0f} MB (rest {rest:.0f}), stop {got['stop_s']:.1f} s, "
              f"events {got['events']}, history {got['health']['history']['state']}")
        assert got["rss"] < 2 * rest, f"{name}: RSS {got['rss']:.0f} MB, at rest {rest:.0f} MB"
        assert got["stop_s"] < STOP_S, f"{name}: SIGTERM took {got['stop_s']:.1f} s"
        assert "Traceback" not in got["log"], got["log"][-3000:]
        assert "not a regular file" in got["log"], got["log"][-3000:]  # said, and left aside
        aside = [p.name for p in spool.iterdir() if p.name.endswith(".notfile")]
        assert aside, f"{name}: the planted file was not set aside: {sorted(os.listdir(spool))}"


def _spool_from_a_real_outage(folder: Path, running_hub, sse_ids, eventually) -> list[int]:
    """A hub whose database's write lock another process holds is stopped: its records wait in the spool.
    Returns the ids the SSE client saw. The pad presses at 240 Hz: the 600 records that wait are made in
    a few seconds, not the ~12 s they take at 60 Hz (the spool holds records, whatever their rate)."""
    hub = running_hub(["-c", str(_config(folder, 240.0))], folder)
    blocker: sqlite3.Connection | None = None
    try:
        info = hub.ready(60)
        reader = sse_ids(info["devices"]["pad"] + "/events")
        eventually(lambda: len(reader.ids) >= 30, 30, "events streamed")
        blocker = sqlite3.connect(folder / "hub.db", timeout=30, isolation_level=None)
        blocker.execute("BEGIN IMMEDIATE")
        seen = len(reader.ids)
        eventually(lambda: len(reader.ids) >= seen + 600, 60, "events made while the database hangs")
        _stop(hub)
        assert "wait in the spool" in hub.log(), hub.log()[-3000:]
        reader.stop()
        return list(reader.ids)
    finally:
        if blocker is not None:
            blocker.execute("ROLLBACK")
            blocker.close()
        hub.kill()


def _stored(db: Path) -> list[int]:
    con = sqlite3.connect(db)
    try:
        return [s for (s,) in con.execute("SELECT e.seq FROM events e JOIN things t ON t.key = e.thing_key "
                                          "WHERE t.id = 'pad' ORDER BY e.id")]
    finally:
        con.close()


def test_a_damaged_spool_keeps_what_can_be_read_and_says_what_it_lost(
        tmp_path, running_hub, sse_ids, eventually):
    made = tmp_path / "made"
    made.mkdir()
    seen = _spool_from_a_real_outage(made, running_hub, sse_ids, eventually)
    before = set(_stored(made / "hub.db"))
    waiting = sorted(set(seen) - before)
    assert len(waiting) >= 600, f"only {len(waiting)} records waited in the spool"
    segs = sorted((made / "hub.db.spool").glob("*.seg"))
    assert segs
    for damage in ("flipped-byte", "broken-header"):
        folder = tmp_path / damage
        shutil.copytree(made, folder, ignore=shutil.ignore_patterns("hub-*.log", "lock"))
        seg = sorted((folder / "hub.db.spool").glob("*.seg"))[-1]
        data = bytearray(seg.read_bytes())
        at = len(data) // 2 if damage == "flipped-byte" else 2
        data[at] ^= 0x40
        seg.write_bytes(bytes(data))
        got = _run_and_measure(folder, running_hub, sse_ids, eventually)
        stored = _stored(folder / "hub.db")
        kept = len(set(waiting) & set(stored))
        spool = got["health"]["history"]["spool"]
        print(f"{damage}: {kept} of {len(waiting)} waiting records reached history; health "
              f"{got['health']['history']['state']}: {got['health']['history']['reason']!r}; "
              f"damaged {spool.get('damaged')}")
        assert len(waiting) - kept <= FRAME_RECORDS, f"{damage}: {kept} of {len(waiting)} kept"
        assert len(stored) == len(set(stored)) and stored == sorted(stored)
        damaged = spool.get("damaged") or []
        assert damaged and got["health"]["history"]["state"] == "degraded", got["health"]["history"]
        lost = len(waiting) - kept
        assert sum(d["records"] for d in damaged) >= lost, (damaged, lost)  # the count of what it held
        assert "could not be read" in got["log"], got["log"][-3000:]
        kept_as = Path(damaged[0]["keptAs"])
        assert kept_as.exists() and kept_as.parent == folder / "hub.db.spool"  # quarantined, not deleted
        assert "Traceback" not in got["log"], got["log"][-3000:]


@pytest.mark.parametrize("target", ["hub.db.hub-id", "hub.db", "hub.db-wal", "hub.db-shm", "hub.db-journal"])
def test_a_fifo_or_dev_zero_as_the_hub_id_file_or_database_is_one_line_not_a_hang(
        tmp_path, running_hub, target):
    """The same attack on the other files the hub reads: its id file beside the database, the database
    file itself, and the files SQLite opens itself beside it (its write-ahead log, shared-memory index,
    rollback journal: ``db.check_sidecars``): before, the start blocked opening the FIFO (SIGTERM
    ignored; for the sidecars inside SQLite's own open) and ``/dev/zero`` would be read without end."""
    for name, plant in (("fifo", S.fifo), ("dev-zero", lambda p: p.symlink_to("/dev/zero"))):
        folder = tmp_path / name
        folder.mkdir()
        plant(folder / target)
        hub = running_hub(["-c", str(_config(folder))], folder)
        try:
            t0 = time.monotonic()
            rc = hub.wait(60)
            took = time.monotonic() - t0
            log = hub.log()
        finally:
            hub.kill()
        print(f"{target} {name}: exit {rc} in {took:.1f} s: {log.strip().splitlines()[-1:]}")
        assert rc is not None and rc != 0, f"{name}: the hub did not end: {log[-2000:]}"
        assert "Traceback" not in log and "not a regular file" in log, log[-3000:]
        named = (f"{target}'", f"{target}:", "'/dev/zero'")  # the file, or where its symlink leads
        assert any(n in log for n in named), log[-3000:]
