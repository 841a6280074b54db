"""Issue 32 items 4 and 6: ``history export`` shows progress on a terminal (and only there), ``replay``
starts at once and says what it is doing, a late subscriber gets a replay from its first record,
and the demo's history is bounded.

The commands run as processes; "a terminal" is a real pseudo-terminal pair on their stderr.
"""

from __future__ import annotations

import json
import os
import pty
import signal
import subprocess
import sys
import threading
from pathlib import Path

import httpx
import pytest
from httpx_sse import connect_sse

from wott_hub.events.record import KIND_EVENT, Record
from wott_hub.examples import example_device
from wott_hub.history import HistoryWriter, create_engine, database_url, upgrade
from wott_hub.td.builder import build_tactile_td, static_property_values

WOTT_HUB = str(Path(sys.executable).with_name("wott-hub"))
N = 3000


@pytest.fixture(scope="module")
def db(tmp_path_factory) -> str:
    path = str(tmp_path_factory.mktemp("history") / "h.db")
    eng = create_engine(database_url(path))
    upgrade(eng)
    w = HistoryWriter(eng, interval_s=0.01, integrity_check=False)
    desc = example_device("flat", "d")
    start = w.register_thing("d", title="d", family="scene", td=json.dumps(build_tactile_td(desc)),
                             static_values=json.dumps(static_property_values(desc)))
    w.start()
    for i in range(N):  # 10 ms apart: 30 s of recording
        w.submit(Record("d", start + i + 1, KIND_EVENT, "tick", 1_700_000_000 * 10**9 + i * 10**7,
                        json.dumps({"i": i})))
    assert w.flush(30)
    w.stop()
    eng.dispose()
    return path


class _Terminal:
    """A pseudo-terminal for a process's stderr: everything written to it, read in a thread."""

    def __init__(self) -> None:
        self.master, self.slave = pty.openpty()
        self.text = ""
        self._thread = threading.Thread(target=self._read, daemon=True)

    def start(self) -> _Terminal:
        os.close(self.slave)  # the child holds its own copy
        self._thread.start()
        return self

    def _read(self) -> None:
        while True:
            try:
                chunk = os.read(self.master, 4096)
            except OSError:  # EIO: the child closed its end
                break
            if not chunk:
                break
            self.text += chunk.decode(errors="replace")

    def close(self) -> str:
        self._thread.join(30)
        os.close(self.master)
        return self.text


def test_export_draws_a_bar_on_a_terminal_only(db, tmp_path, cli):
    term = _Terminal()
    out = tmp_path / "out.jsonl"
    args = ["history", "export", "--device", "d", "--database", db, "-o", str(out)]
    proc = subprocess.Popen([WOTT_HUB, *args], stderr=term.slave, stdout=subprocess.DEVNULL,
                            env={**os.environ, "COLUMNS": "80"})
    term.start()
    assert proc.wait(120) == 0
    shown = term.close()
    assert "export d" in shown and "%" in shown, shown  # rich's bar, its percentage
    assert shown.rstrip().endswith(f"{N} records")
    assert len(out.read_text().splitlines()) == N
    res = cli("history", "export", "--device", "d", "--database", db, "-o", str(out))  # stderr: a pipe
    assert res.returncode == 0 and res.stderr == f"{N} records\n"
    term = _Terminal()
    proc = subprocess.Popen([WOTT_HUB, "history", "export", "--device", "d", "--database", db, "-o", str(out),
                             "--no-progress"], stderr=term.slave, stdout=subprocess.DEVNULL)
    term.start()
    assert proc.wait(120) == 0
    assert term.close().strip() == f"{N} records"


def _start_replay(db: str, stderr) -> tuple[subprocess.Popen[str], dict]:
    args = ["replay", "--device", "d", "--database", db, "--port", "0", "--ws-port", "0", "--json"]
    proc = subprocess.Popen([WOTT_HUB, *args], stdout=subprocess.PIPE, stderr=stderr, text=True)
    assert proc.stdout is not None
    line = proc.stdout.readline()
    assert line, proc.poll()
    return proc, json.loads(line)


def _stop(proc: subprocess.Popen[str]) -> None:
    proc.send_signal(signal.SIGINT)
    try:
        assert proc.wait(60) == 0
    finally:
        if proc.poll() is None:
            proc.kill()


def test_a_replay_starts_at_once_and_a_late_subscriber_gets_it_from_the_first_record(db):
    proc, info = _start_replay(db, subprocess.DEVNULL)
    try:
        assert info["thing"] == "replay-d" and info["events"].endswith("/wot/replay-d/events")
        got = []
        with httpx.Client(timeout=60) as c, connect_sse(c, "GET", info["events"],
                                                        headers={"Last-Event-ID": "0"}) as es:
            for ev in es.iter_sse():
                if not ev.data:  # the stream's opening retry: field
                    continue
                got.append(json.loads(ev.data)["i"])
                if len(got) == 20:
                    break
        assert got == list(range(20))  # from the first record on, however late the subscription came
    finally:
        _stop(proc)


def test_replay_says_what_it_does_while_it_starts_on_a_terminal(db):
    term = _Terminal()
    proc, info = _start_replay(db, term.slave)
    term.start()
    try:
        assert info["thing"] == "replay-d"
    finally:
        _stop(proc)
    shown = term.close()
    said = ("replay: opening the history database", "replay: starting the replay server")
    assert any(s in shown for s in said), shown
    assert "Traceback" not in shown


def test_the_demo_keeps_its_history_bounded_and_a_config_file_keeps_all():
    from wott_hub.config import DEMO_RETENTION_MB, HubConfig

    demo = HubConfig.demo_config()
    assert demo.retention_mb == DEMO_RETENTION_MB == 500 and demo.retention.active
    assert HubConfig.from_dict({"hub": {}}).retention_mb is None
    assert HubConfig.demo_config(retention_mb=50).retention_mb == 50
