"""Issue 16, item 10 (history parts): ``history``/``replay`` end bad input with one line and a
non-zero exit, never a Python or Alembic traceback, and never create or migrate a database;
non-finite numbers never become (invalid) JSON in a record.

Each case runs the real ``wott-hub`` command in a subprocess on real SQLite files.
"""

from __future__ import annotations

import json
import math
import os
import sqlite3
import subprocess
import sys

import pytest

from wott_hub.events.record import KIND_EVENT, Record, encode
from wott_hub.history import HistoryWriter, create_engine, database_url, upgrade


@pytest.fixture(scope="module")
def good(tmp_path_factory) -> str:
    db = str(tmp_path_factory.mktemp("cli") / "h.db")
    eng = create_engine(database_url(db))
    upgrade(eng)
    w = HistoryWriter(eng, interval_s=0.01)
    start = w.register_thing("d", td=json.dumps({"title": "d"}))
    w.start()
    for i in range(10):
        t_ns = 1_700_000_000 * 10**9 + i
        w.submit(Record("d", start + i + 1, KIND_EVENT, "tick", t_ns, json.dumps({"i": i})))
    assert w.flush(10)
    w.stop()
    eng.dispose()
    return db


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", "from wott_hub.cli import main; main()", *args],
                          capture_output=True, text=True, timeout=60)


def _one_error_line(res: subprocess.CompletedProcess) -> str:
    assert res.returncode != 0, res.stdout
    assert "Traceback" not in res.stderr, res.stderr
    lines = [ln for ln in res.stderr.splitlines() if ln.strip() and not ln.startswith("Bytecode compiled")]
    assert len(lines) == 1 and lines[0].startswith("error: "), res.stderr
    return lines[0]


@pytest.mark.parametrize(("args", "code", "says"), [
    (("--from", "2262-05-01"), 2, "out of range"),
    (("--from", "1e30"), 2, "out of range"),
    (("--from", "nan"), 2, "not a time"),
    (("--from", "-99999999999999999999d"), 2, "out of range: '-99999999999999999999d'"),
    (("--from", "2026-01-02", "--to", "2026-01-01"), 2, "is after --to"),
    (("--output", "/nonexistent-folder/out.jsonl"), 2, "does not exist"),
    (("--device", "nobody"), 3, "no recorded device 'nobody'"),
])
def test_history_export_bad_input_is_one_line(good, args, code, says):
    device = () if "--device" in args else ("--device", "d")
    res = _cli("history", "export", *device, *args, "--database", good)
    line = _one_error_line(res)
    assert res.returncode == code and says in line


def test_history_export_of_a_good_range_still_works(good):
    res = _cli("history", "export", "--device", "d", "--from", "1700000000", "--database", good)
    assert res.returncode == 0, res.stderr
    assert [json.loads(ln)["data"]["i"] for ln in res.stdout.splitlines()] == list(range(10))


def test_a_database_of_a_newer_schema_is_refused_not_migrated(good, tmp_path):
    db = tmp_path / "newer.db"
    # SQLite's backup, not a file copy: the database is in WAL mode, and what a file copy misses while a
    # connection still holds the WAL (a writer thread finishing on a loaded machine) is its schema
    with sqlite3.connect(good) as src, sqlite3.connect(db) as dst:
        src.backup(dst)
    with sqlite3.connect(db) as conn:
        conn.execute("UPDATE alembic_version SET version_num = '9999'")
    for args in (("history", "list"), ("replay", "--device", "d", "--port", "0", "--ws-port", "0")):
        line = _one_error_line(_cli(*args, "--database", str(db)))
        assert "revision '9999'" in line and "newer wott-hub" in line
    with sqlite3.connect(db) as conn:
        assert conn.execute("SELECT version_num FROM alembic_version").fetchall() == [("9999",)]


def test_an_unknown_database_url_scheme_is_one_line():
    line = _one_error_line(_cli("history", "list", "--database", "nosuchdb://host/x"))
    assert "nosuchdb://host/x" in line


def test_history_list_neither_creates_nor_migrates(tmp_path):
    missing = tmp_path / "missing.db"
    assert "no history database at" in _one_error_line(_cli("history", "list", "--database", str(missing)))
    assert not missing.exists()
    empty = tmp_path / "empty.db"
    empty.touch()
    assert "is empty" in _one_error_line(_cli("history", "list", "--database", str(empty)))
    assert empty.stat().st_size == 0 and sorted(p.name for p in tmp_path.iterdir()) == ["empty.db"]


@pytest.mark.parametrize(("args", "says"), [
    (("--speed", "nan"), "--speed must be a finite number >= 0"),
    (("--speed", "-1"), "--speed must be a finite number >= 0"),
    (("--delay", "inf"), "--delay must be a finite number >= 0"),
])
def test_replay_bad_numbers_are_one_line(good, args, says):
    assert says in _one_error_line(_cli("replay", "--device", "d", *args, "--database", good))


def test_replay_never_creates_a_database_at_a_mistyped_path(tmp_path):
    typo = tmp_path / "hsitory.db"
    line = _one_error_line(_cli("replay", "--device", "d", "--database", str(typo)))
    assert "no history database at" in line and str(typo) in line
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_non_finite_number_never_becomes_record_json(bad):
    with pytest.raises(ValueError, match="JSON compliant"):
        encode({"contactForces": [{"x": 0.0, "y": bad, "z": 0.0}]})
    assert json.loads(encode({"x": 1e300})) == {"x": 1e300}  # large but finite is fine


@pytest.mark.parametrize("suffix", ["-wal", "-shm", "-journal"])
def test_a_fifo_beside_the_database_where_sqlite_opens_its_own_files_is_one_line(good, tmp_path, suffix):
    """Issue 48: SQLite opens its write-ahead log, shared-memory index and rollback journal itself; a FIFO
    named so beside the database blocked the open (a ``-journal`` FIFO for ever: no timeout reaches inside
    SQLite). ``history`` and ``replay`` refuse it with one line naming the file, nothing opened."""
    db = tmp_path / "h.db"
    with sqlite3.connect(good) as src, sqlite3.connect(db) as dst:
        src.backup(dst)
    for side in tmp_path.glob("h.db-*"):  # what SQLite's backup left beside the copy
        side.unlink()
    fifo = tmp_path / f"h.db{suffix}"
    os.mkfifo(fifo)
    for args in (("history", "list"), ("replay", "--device", "d", "--port", "0", "--ws-port", "0")):
        line = _one_error_line(_cli(*args, "--database", str(db)))
        assert f"h.db{suffix}' is not a regular file" in line, line
    assert fifo.exists() and sorted(p.name for p in tmp_path.iterdir()) == sorted(["h.db", fifo.name])
