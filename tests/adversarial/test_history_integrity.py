"""Issue 16, item 7: a database corrupted mid-file is reported, never served as a silent empty stream.

A real SQLite file with 20 000 records (~10 MB) has 64 KB in its middle overwritten; then the CLI,
the writer's health and a real hub's SSE resume are asked about it.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import httpx
import pytest

from wott_hub.config import HubConfig
from wott_hub.events.record import KIND_EVENT, Record
from wott_hub.history import HistoryWriter, create_engine, database_url, upgrade
from wott_hub.history.state import state_of
from wott_hub.network import DirectoryConfig

N = 20_000
_TD = {"@context": "https://www.w3.org/2022/wot/td/v1.1", "title": "d", "id": "urn:test:d",
       "securityDefinitions": {"n": {"scheme": "nosec"}}, "security": "n",
       "events": {"tick": {"data": {"type": "object"}}}}


@pytest.fixture(scope="module")
def corrupted(tmp_path_factory) -> str:
    db = str(tmp_path_factory.mktemp("corrupt") / "h.db")
    eng = create_engine(database_url(db))
    upgrade(eng)
    w = HistoryWriter(eng, interval_s=0.01, integrity_check=False)
    start = w.register_thing("d")
    w.start()
    for i in range(N):
        w.submit(Record("d", start + i + 1, KIND_EVENT, "tick", 10**18 + i,
                        json.dumps({"i": i, "pad": "x" * 400})))
    assert w.flush(30)
    w.stop()
    eng.dispose()  # the last connection checkpoints the WAL into the file
    size = os.path.getsize(db)
    with open(db, "r+b") as f:
        f.seek(size // 2 // 4096 * 4096)
        f.write(os.urandom(4096 * 16))
    return db


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", "from wott_hub.cli import main; main()", *args],
                          capture_output=True, text=True, timeout=60)


@pytest.mark.parametrize("args", [("history", "export", "--device", "d"), ("history", "list", "--check")])
def test_the_cli_says_corrupted_in_one_line_and_exits_non_zero(corrupted, args):
    res = _cli(*args, "--database", corrupted)
    assert res.returncode == 6, res.stderr
    lines = [ln for ln in res.stderr.splitlines() if not ln.startswith("Bytecode compiled")]
    assert len(lines) == 1 and lines[0].startswith("error: ") and "corrupted" in lines[0], res.stderr
    assert corrupted in lines[0]
    assert "Traceback" not in res.stderr and res.stdout == ""


def test_the_writer_reports_degraded_health_after_its_integrity_check(corrupted):
    eng = create_engine(database_url(corrupted))
    w = HistoryWriter(eng, interval_s=0.01)
    w.start()
    try:
        deadline = time.monotonic() + 20
        while w.health()["integrity"] == "unchecked" and time.monotonic() < deadline:
            time.sleep(0.05)
        h = w.health()
        assert h["state"] == "degraded" and "corrupted" in h["reason"] and "Page" in h["integrity"]
    finally:
        w.stop()
        eng.dispose()


@pytest.fixture
def hub_on(hub_thread, corrupted):
    def start():
        cfg = HubConfig(name="corrupt", host="127.0.0.1", http_port=0, ws_port=0, database=corrupted,
                        directory=DirectoryConfig(enabled=False))
        h = hub_thread(cfg).start()
        started.append(h)
        h.call(h.hub.expose_thing, "d", _TD, record=True)
        return h

    started: list = []
    yield start
    for h in started:
        h.stop()


def _writer(hub):
    return hub._history.writer


def _checked(hub) -> None:
    """Wait for the writer's start-up integrity check to have said what it found."""
    deadline = time.monotonic() + 20
    while _writer(hub).health()["integrity"] == "unchecked" and time.monotonic() < deadline:
        time.sleep(0.05)


def test_an_sse_resume_needing_corrupted_history_is_refused_with_503(hub_on):
    h = hub_on()
    _checked(h.hub)
    assert _writer(h.hub).health()["state"] == "degraded"
    url = h.hub.td_url("d") + "/events"
    with httpx.Client(timeout=10) as c:
        r = c.get(url, headers={"Accept": "text/event-stream", "Last-Event-ID": "5"})
    assert r.status_code == 503
    assert r.headers["content-type"].startswith("application/problem+json")
    assert "corrupted" in r.json()["title"]


def test_a_read_error_during_a_resume_ends_the_stream_with_an_error_not_in_silence(hub_on):
    h = hub_on()
    # as if the start-up check had not seen it: the read itself must say so. Its verdict is
    # overwritten once it is in (written after this line, it would refuse the resume with a 503)
    _checked(h.hub)
    state_of(_writer(h.hub).storage.engine).integrity = "ok"
    url = h.hub.td_url("d") + "/events"
    with httpx.Client(timeout=10) as c, c.stream(
            "GET", url, headers={"Accept": "text/event-stream", "Last-Event-ID": "5"}) as r:
        assert r.status_code == 200
        body = b""
        deadline = time.monotonic() + 15
        for chunk in r.iter_bytes():
            body += chunk
            if b": error:" in body or time.monotonic() > deadline:
                break
    text = body.decode()
    assert ": error:" in text and "malformed" in text
    assert _writer(h.hub).health()["state"] == "degraded"
