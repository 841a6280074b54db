"""What the adversarial tests share: a real directory server in a thread; real hub processes started as
users start them (``uv run``), SSE readers, a Mosquitto broker (issue 33)."""

from __future__ import annotations

import asyncio
import contextlib
import threading
from typing import Any

import pytest
from wott_directory import Directory, DirectoryServer, DirectorySettings


class DirectoryThread:
    """A real directory server in a thread with its own event loop."""

    def __init__(self, token: str, db: str = "sqlite://", **settings: Any) -> None:
        self.settings = DirectorySettings(token=token, **settings)  # budgets etc. beside the token
        self.db = db
        self.loop = asyncio.new_event_loop()
        self.server: DirectoryServer | None = None
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        asyncio.set_event_loop(self.loop)
        self.server = self.loop.run_until_complete(DirectoryServer(Directory(self.settings, self.db)).start())
        self._ready.set()
        self.loop.run_forever()

    def start(self) -> DirectoryThread:
        self._thread.start()
        assert self._ready.wait(30), "the directory did not start"
        return self

    @property
    def url(self) -> str:
        assert self.server is not None
        return self.server.url

    @property
    def directory(self) -> Directory:
        assert self.server is not None
        return self.server.directory

    def stop(self) -> None:
        assert self.server is not None
        asyncio.run_coroutine_threadsafe(self.server.stop(), self.loop).result(30)
        self.loop.call_soon_threadsafe(self.loop.stop)
        self._thread.join(10)


@pytest.fixture(scope="session")
def directory_thread() -> type[DirectoryThread]:
    """``directory_thread(token, db).start()``: a started ``DirectoryThread`` (stop it yourself)."""
    return DirectoryThread


# --- issue 33: real hub processes, signals, SSE readers, a broker -------------------------------------------

class RunningHub:
    """``uv run wott-hub run --json`` as a user types it, in a session of its own: ``signal`` sends to the
    whole process group (uv and the hub), as a terminal's Ctrl-C or a service manager's SIGTERM does."""

    def __init__(self, args: list[str], cwd, env: dict[str, str] | None = None) -> None:
        import os
        import shutil
        import subprocess
        from pathlib import Path

        uv = os.environ.get("UV") or shutil.which("uv")
        assert uv, "uv not found: run the tests with `uv run pytest`"
        root = Path(__file__).resolve().parents[2]
        n = 1
        while (Path(cwd) / f"hub-{n}.log").exists():  # each run of a test's hubs keeps its own log
            n += 1
        self.log_path = Path(cwd) / f"hub-{n}.log"
        self._log = self.log_path.open("w")
        cmd = [uv, "run", "--no-sync", "--project", str(root), "wott-hub", "run", "--json",
               "--log-level", "info", *args]
        self.proc = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=self._log, text=True,
                                     start_new_session=True, env={**os.environ, **(env or {})})
        self.info: dict | None = None

    def ready(self, timeout: float = 60) -> dict:
        """The hub's describe() line (waiting for it at most ``timeout`` s)."""
        import json

        box: list[str] = []
        t = threading.Thread(target=lambda: box.append(self.proc.stdout.readline()), daemon=True)
        t.start()
        t.join(timeout)
        assert box and box[0], f"the hub did not start: {self.log()[-3000:]}"
        self.info = json.loads(box[0])
        return self.info

    def signal(self, sig: int) -> None:
        import os

        os.killpg(self.proc.pid, sig)

    def wait(self, timeout: float) -> int | None:
        """The exit code, or None if still running after ``timeout`` s."""
        import subprocess

        try:
            return self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            return None

    def log(self) -> str:
        self._log.flush()
        return self.log_path.read_text(errors="replace")

    def stop(self, timeout: float = 30) -> None:
        """A clean stop (SIGTERM to the group), SIGKILL after ``timeout``: a killed hub leaves its
        database's lease to expire, and a hub started on that database meanwhile is refused."""
        import signal

        if self.proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                self.signal(signal.SIGTERM)
            self.wait(timeout)
        self.kill()

    def kill(self) -> None:
        import os
        import signal

        if self.proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait(30)
        if self.proc.stdout is not None:
            self.proc.stdout.close()
        self._log.close()


class SseIds:
    """A real SSE client in a thread: every event id it reads (``ids``) and when (``at``); it ends when
    the stream does (the hub stopped) or at ``stop``."""

    def __init__(self, url: str, headers: dict[str, str] | None = None) -> None:
        self.url = url
        self.headers = {"Accept": "text/event-stream", **(headers or {})}
        self.ids: list[int] = []
        self.at: list[float] = []
        self.opened = threading.Event()
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        import time

        import httpx

        try:
            with httpx.Client(timeout=httpx.Timeout(10, read=60)) as c, \
                    c.stream("GET", self.url, headers=self.headers) as r:
                self.opened.set()
                for line in r.iter_lines():
                    if line.startswith("id:"):
                        self.ids.append(int(line[3:]))
                        self.at.append(time.monotonic())
                    if self._stop.is_set():
                        return
        except httpx.HTTPError:  # the hub went away: what was read is read
            pass
        finally:
            self.opened.set()

    def longest_gap(self, since: float = 0.0) -> float:
        """The longest time between two events read after ``since`` (time.monotonic())."""
        times = [t for t in self.at if t >= since]
        return max((b - a for a, b in zip(times, times[1:], strict=False)), default=0.0)

    def stop(self) -> None:
        self._stop.set()
        self.thread.join(15)


class Broker:
    """One real Mosquitto on 127.0.0.1 (Debian's package; missing: a failure naming it, never a skip)."""

    def __init__(self, folder) -> None:
        import shutil
        import socket
        from pathlib import Path

        binary = shutil.which("mosquitto") or next(
            (p for p in ("/usr/sbin/mosquitto", "/usr/local/sbin/mosquitto") if Path(p).exists()), None)
        if binary is None:
            pytest.fail("mosquitto not found: .ci/run installs it (apt-get install mosquitto)", pytrace=False)
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            self.port = s.getsockname()[1]
        conf = Path(folder) / "mosquitto.conf"
        conf.write_text(f"listener {self.port} 127.0.0.1\nallow_anonymous true\npersistence false\n")
        self.log = Path(folder) / "mosquitto.log"
        import subprocess

        with self.log.open("ab") as log:
            self.proc = subprocess.Popen([binary, "-c", str(conf)], stdout=log, stderr=log)

    @property
    def url(self) -> str:
        return f"mqtt://127.0.0.1:{self.port}"

    def listening(self) -> bool:
        import socket

        with socket.socket() as s:
            return s.connect_ex(("127.0.0.1", self.port)) == 0

    def retained(self, prefix: str, timeout: float = 10.0) -> dict[str, bytes]:
        """The retained messages under ``prefix``: what a new subscriber gets. The broker sends them when
        it handles the SUBSCRIBE, so a message this client publishes after its SUBACK comes after them:
        its arrival says the retained ones are all in."""
        import uuid

        import paho.mqtt.client as mqtt

        got: dict[str, bytes] = {}
        subscribed, done = threading.Event(), threading.Event()
        sentinel = f"{prefix}/zz-sentinel/{uuid.uuid4().hex}"

        def on_message(_c, _u, m) -> None:
            if m.topic == sentinel:
                done.set()
            elif m.retain:
                got[m.topic] = m.payload

        client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2)
        client.on_message = on_message
        client.on_subscribe = lambda *_a: subscribed.set()
        client.connect("127.0.0.1", self.port)
        client.loop_start()
        try:
            client.subscribe(f"{prefix}/#", qos=1)
            assert subscribed.wait(timeout), "no SUBACK from the broker"
            client.publish(sentinel, b"end", qos=1)
            assert done.wait(timeout), "the sentinel message did not come back"
        finally:
            client.loop_stop()
            client.disconnect()
        return {t: p for t, p in got.items() if p}

    def stop(self) -> None:
        import subprocess

        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


@pytest.fixture(scope="session")
def running_hub() -> type[RunningHub]:
    """``running_hub(args, cwd, env=None)``: ``uv run wott-hub run`` in a process group of its own."""
    return RunningHub


@pytest.fixture(scope="session")
def sse_ids() -> type[SseIds]:
    """``sse_ids(url, headers=None)``: an SSE reader thread collecting event ids and their times."""
    return SseIds


@pytest.fixture
def broker(tmp_path, eventually):
    b = Broker(tmp_path)
    try:
        eventually(b.listening, 10, "mosquitto listening")
        yield b
    finally:
        b.stop()
