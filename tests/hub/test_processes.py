"""``wott-hub run`` as a real process: SIGKILL mid-stream and restart; SIGTERM; history and replay CLIs."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from wott_hub.events.record import KIND_EVENT
from wott_hub.history import HistoryReader, create_engine, database_url

WOTT_HUB = str(Path(sys.executable).parent / "wott-hub")

CONFIG = """
[hub]
name = "crash-test"
http_port = 0
ws_port = 0
database = "hub.db"
history_batch_ms = 20

[[device]]
id = "pad"
family = "scene"
shape = "flat"
rate_hz = 240
loop = true
step = [
  {{ kind = "press", at = {a}, start_s = 0.0, duration_s = 0.5, depth_mm = 1.0, radius_mm = 4.0 }},
  {{ kind = "slide", at = {b}, to = {a}, start_s = 0.5, duration_s = 0.5, depth_mm = 1.0, radius_mm = 4.0 }},
]
"""


@pytest.fixture
def config_file(tmp_path):
    from wott_hub.examples import example_device

    mesh = example_device("flat").mesh
    free = mesh.free_indices
    a = [round(float(v), 3) for v in mesh.nodes[free[len(free) // 2]]]
    b = [round(float(v), 3) for v in mesh.nodes[free[len(free) // 3]]]
    path = tmp_path / "hub.toml"
    path.write_text(CONFIG.format(a=a, b=b))
    return path


_STARTED: list[subprocess.Popen] = []


@pytest.fixture(autouse=True)
def _end_processes():
    """What a test started is gone after it, its pipes closed, whatever the test asserted."""
    yield
    while _STARTED:
        proc = _STARTED.pop()
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
        proc.stdout.close()
        proc.stderr.close()


def _start(args, cwd) -> tuple[subprocess.Popen, dict]:
    proc = subprocess.Popen([WOTT_HUB, *args], cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    _STARTED.append(proc)
    line = proc.stdout.readline()
    if not line:
        proc.kill()
        raise AssertionError(f"{args} did not start: {proc.stderr.read()}")
    return proc, json.loads(line)


@pytest.fixture(scope="module")
def read_sse(sse_events):
    """The first n events of a stream as (id, data), resuming after ``last_id`` if given."""
    def read(url, n, last_id=None):
        headers = {"Last-Event-ID": str(last_id)} if last_id is not None else {}
        return [(int(ev.id), ev.data) for ev in sse_events(url, n, headers=headers, timeout=15)]

    return read


def _rows(db):
    """Every recorded record of "pad" (events and property changes): seq -> (kind, data)."""
    engine = create_engine(database_url(db))
    try:
        return {r.seq: (r.kind, r.data) for page in HistoryReader(engine).pages("pad") for r in page}
    finally:
        engine.dispose()


def _written(info) -> int:
    """Records the hub reports as committed to its history."""
    return int(httpx.get(f"{info['hub']}/properties/eventCounters").json()["history"]["written"])


def test_sigkill_mid_stream_then_restart_loses_nothing_committed(config_file, tmp_path, read_sse):
    proc, info = _start(["run", "--config", str(config_file), "--json"], tmp_path)
    try:
        events_url = f"{info['devices']['pad']}/events"
        seen = read_sse(events_url, 150)
        deadline = time.monotonic() + 15  # the stream can run ahead of the first commit (a batch,
        while (committed := _written(info)) == 0 and time.monotonic() < deadline:  # its process)
            time.sleep(0.05)
        assert committed > 0
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
    rows = _rows(tmp_path / "hub.db")  # opens fine after the crash
    assert len(rows) >= committed  # everything the hub had reported as committed is there
    seqs = sorted(rows)
    assert seqs == list(range(1, seqs[-1] + 1))  # committed history has no hole
    for seq, data in seen:
        if seq in rows:
            assert rows[seq] == (KIND_EVENT, data)  # what was committed is what clients got
    last_seen = seen[-1][0]

    proc, info = _start(["run", "--config", str(config_file), "--json"], tmp_path)
    try:
        resumed = read_sse(f"{info['devices']['pad']}/events", 100, last_id=last_seen)
    finally:
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(30) == 0, proc.stderr.read()[-3000:]  # clean shutdown
    ids = [i for i, _ in resumed]
    assert ids == sorted(set(ids)) and ids[0] > last_seen  # the sequence continues, nothing reused
    rows_after = _rows(tmp_path / "hub.db")
    assert all(rows_after[s] == d for s, d in rows.items())  # the first run's history is intact
    assert all(rows_after[i] == (KIND_EVENT, d) for i, d in resumed)  # SIGTERM wrote everything streamed


def test_history_and_replay_commands(config_file, tmp_path, read_sse, sse_events):
    proc, info = _start(["run", "--config", str(config_file), "--json"], tmp_path)
    try:
        read_sse(f"{info['devices']['pad']}/events", 200)
    finally:
        proc.send_signal(signal.SIGINT)
        assert proc.wait(30) == 0, proc.stderr.read()[-3000:]
    db = str(tmp_path / "hub.db")
    listing = subprocess.run([WOTT_HUB, "history", "list", "--database", db, "--json", "--count"],
                             capture_output=True, text=True, check=True)
    (pad,) = json.loads(listing.stdout)
    assert pad["id"] == "pad" and pad["family"] == "scene" and pad["count"] >= 200
    out = tmp_path / "pad.jsonl"
    t_from = str(pad["first_t_ns"])
    subprocess.run([WOTT_HUB, "history", "export", "--device", "pad", "--database", db, "--from", t_from,
                    "-o", str(out)], check=True, capture_output=True)
    lines = [json.loads(x) for x in out.read_text().splitlines()]
    assert len(lines) == pad["count"] and [x["seq"] for x in lines] == sorted(x["seq"] for x in lines)

    recorded = [(x["name"], x["data"]) for x in lines if x["kind"] == "event"]
    proc, rinfo = _start(["replay", "--device", "pad", "--database", db, "--speed", "4", "--port", "0",
                          "--ws-port", "0", "--json", "--delay", "1.5"], tmp_path)
    try:
        td = httpx.get(rinfo["td"]).json()
        assert td["title"].endswith("(replay)") and "skinDeformedDetection" in td["events"]
        got = [(ev.event, json.loads(ev.data)) for ev in sse_events(rinfo["events"], 50, timeout=15)]
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(30)
    assert got == recorded[:50]


def test_run_without_arguments_serves_the_demo_and_stops_cleanly(tmp_path):
    t0 = time.monotonic()
    proc, info = _start(["run", "--port", "0", "--ws-port", "0", "--json"], tmp_path)
    try:
        assert info["devices"], info
        catalogue = httpx.get(f"{info['http']}/wot").json()
        assert set(info["devices"]) | {"hub"} <= set(catalogue)
        assert info["database"].endswith("wott-hub.db")  # SQLite in the working folder
        assert info["ready_s"] <= time.monotonic() - t0 + 1  # reported from the process start
    finally:
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(30) == 0, proc.stderr.read()[-3000:]
    assert (tmp_path / "wott-hub.db").exists()
