"""What the tests of the hub's surroundings share (issue 33, part B): measuring what an attack did to
another client, and the real parts they start.

Imported by each test module as ``from . import surroundings as S``. Nothing here is a mock:
``GapMeter`` is a real SSE client in a thread, ``Broker`` a real Mosquitto, ``HubProcess`` the
real ``wott-hub run``.

- ``GapMeter(url)``: reads an SSE stream in a thread and keeps when each event came;
  ``longest_gap(since)`` is the longest silence between two events (or since the last one), the
  number an attack that stalls the event loop makes large.
- ``Broker``: Mosquitto on a free port of 127.0.0.1 (no persistence); ``pause``/``resume``: the
  broker that accepts and never reads (SIGSTOP/SIGCONT).
- ``retained(url, topic_filter)``: the retained messages a fresh subscriber gets.
- ``HubProcess``: ``wott-hub run --json`` with a config, its log in a file, stopped by signal.
- ``rss_mb(pid)``: resident memory, from ``/proc``.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest

WOTT_HUB = str(Path(sys.executable).with_name("wott-hub"))


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def rss_mb(pid: int | str = "self") -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise AssertionError("no VmRSS in /proc")


class GapMeter:
    """An SSE client in a thread: when each event arrived (``times``), and the longest silence."""

    def __init__(self, url: str, headers: dict[str, str] | None = None) -> None:
        self.url = url
        self.headers = headers or {}
        self.times: list[float] = []
        self.error: BaseException | None = None
        self._stop = threading.Event()
        self._response: Any = None
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        import httpx
        from httpx_sse import connect_sse

        try:
            with httpx.Client(timeout=httpx.Timeout(10, read=60)) as client, \
                    connect_sse(client, "GET", self.url, headers=self.headers) as source:
                self._response = source.response
                for _ in source.iter_sse():
                    self.times.append(time.monotonic())
                    if self._stop.is_set():
                        return
        except Exception as e:  # a stream cut by stop() ends here too
            if not self._stop.is_set():
                self.error = e

    def start(self, first_within: float = 30.0) -> GapMeter:
        self._thread.start()
        deadline = time.monotonic() + first_within
        while not self.times:
            assert self.error is None, f"the SSE stream {self.url} failed: {self.error!r}"
            assert time.monotonic() < deadline, f"no event on {self.url} within {first_within} s"
            time.sleep(0.05)
        return self

    def longest_gap(self, since: float) -> float:
        """The longest time without an event from ``since`` (a ``time.monotonic()``) until now."""
        points = [since, *[t for t in self.times if t > since], time.monotonic()]
        return max(b - a for a, b in zip(points, points[1:], strict=False))

    def count(self, since: float) -> int:
        return sum(1 for t in self.times if t > since)

    def stop(self) -> None:
        self._stop.set()
        if self._response is not None:
            try:
                self._response.close()
            except Exception:  # closing from another thread: the reader ends with an error, ignored
                pass
        self._thread.join(10)


def mosquitto() -> str:
    found = shutil.which("mosquitto") or next(
        (p for p in ("/usr/sbin/mosquitto", "/usr/local/sbin/mosquitto") if Path(p).exists()), None)
    if found is None:
        pytest.fail("mosquitto not found (apt-get install mosquitto): these tests need a real broker",
                    pytrace=False)
    return found


class Broker:
    """One Mosquitto on 127.0.0.1, no persistence."""

    def __init__(self, folder: Path) -> None:
        self.port = free_port()
        self.conf = folder / "mosquitto.conf"
        self.conf.write_text(f"listener {self.port} 127.0.0.1\nallow_anonymous true\npersistence false\n")
        self.log = folder / "mosquitto.log"
        self.proc: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"mqtt://127.0.0.1:{self.port}"

    def start(self) -> Broker:
        with self.log.open("ab") as log:
            self.proc = subprocess.Popen([mosquitto(), "-c", str(self.conf)], stdout=log, stderr=log)
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", self.port)) == 0:
                    return self
            time.sleep(0.05)
        raise AssertionError(f"mosquitto did not listen: {self.log.read_text()[-2000:]}")

    def pause(self) -> None:
        """The broker keeps its connections and never reads them again (until ``resume``)."""
        assert self.proc is not None
        self.proc.send_signal(signal.SIGSTOP)

    def resume(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGCONT)

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.resume()
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


def retained(broker_url: str, topic_filter: str, wait_s: float = 1.0) -> dict[str, bytes]:
    """Topic -> payload of each retained message a new subscriber to ``topic_filter`` gets
    (non-empty ones: an empty retained message is a deletion)."""
    import paho.mqtt.client as mqtt

    host, _, port = broker_url.removeprefix("mqtt://").partition(":")
    got: dict[str, bytes] = {}
    done = threading.Event()

    def on_connect(client: Any, *_: Any) -> None:
        client.subscribe(topic_filter, qos=1)

    def on_message(_client: Any, _userdata: Any, msg: Any) -> None:
        if msg.retain and msg.payload:
            got[msg.topic] = bytes(msg.payload)

    client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2)
    client.on_connect = on_connect
    client.on_message = on_message
    client.connect(host, int(port or 1883))
    client.loop_start()
    try:
        done.wait(wait_s)  # retained messages come right after the subscription
    finally:
        client.loop_stop()
        client.disconnect()
    return got


def retained_json(broker_url: str, topic: str) -> Any:
    payload = retained(broker_url, topic).get(topic)
    return None if payload is None else json.loads(payload)


class HubProcess:
    """``wott-hub run --json`` with ``args`` in ``cwd``: ``info`` (its describe() line), its log."""

    def __init__(self, args: list[str], cwd: Path, log_level: str = "info") -> None:
        self.log_path = cwd / "hub.log"
        self._log = self.log_path.open("w")
        self.proc = subprocess.Popen([WOTT_HUB, "run", "--json", "--log-level", log_level, *args], cwd=cwd,
                                     stdout=subprocess.PIPE, stderr=self._log, text=True)
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        if not line:
            self.proc.wait(10)
            raise AssertionError(f"the hub did not start: {self.log_path.read_text()[-3000:]}")
        self.info = json.loads(line)

    @property
    def log(self) -> str:
        return self.log_path.read_text(errors="replace")

    def stop(self, sig: int = signal.SIGTERM, timeout: float = 30) -> float:
        """Send ``sig`` and wait; returns how long the process took to end (killed after ``timeout``)."""
        t0 = time.monotonic()
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
                self._log.close()
                raise AssertionError(f"the hub did not end within {timeout} s of signal {sig}") from None
        self._log.close()
        return time.monotonic() - t0


def write_config(folder: Path, body: str) -> Path:
    path = folder / "hub.toml"
    path.write_text(body)
    return path


def press_table(device_id: str = "pad", rate_hz: float = 60.0) -> str:
    """A ``[[device]]`` table: a flat skin pressed now and then (the stream a ``GapMeter`` reads)."""
    from wott_hub.examples import example_device

    mesh = example_device("flat").mesh
    at = [round(float(v), 3) for v in mesh.nodes[mesh.free_indices[len(mesh.free_indices) // 2]]]
    return (f'[[device]]\nid = "{device_id}"\nfamily = "scene"\nshape = "flat"\nloop = true\n'
            f'rate_hz = {rate_hz}\n'
            f'step = [{{ kind = "press", at = {at}, start_s = 0.05, duration_s = 0.3, depth_mm = 1.0, '
            f'radius_mm = 4.0 }}]\n')


def fifo(path: Path) -> Path:
    os.mkfifo(path)
    return path


def unblock_fifo(path: Path) -> None:
    """Whoever is blocked opening ``path`` for reading gets it, and its end at once."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK)
    except OSError:  # nobody is reading it
        return
    os.close(fd)


@contextlib.contextmanager
def small_disk(folder: Path, size: str):
    """A tmpfs of ``size`` (mount's spelling: "8k", "16m") at ``folder``: a disk the test fills, unmounted
    at the end (lazily if something still holds it). Root only, as CI runs: without it the test fails
    saying so, it is not skipped."""
    if os.geteuid() != 0:
        pytest.fail("a full disk is a tmpfs mounted by the test: run it as root (CI does)", pytrace=False)
    folder.mkdir(parents=True, exist_ok=True)
    subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(folder)], check=True)
    try:
        yield folder
    finally:
        if subprocess.run(["umount", str(folder)], capture_output=True).returncode != 0:
            subprocess.run(["umount", "-l", str(folder)], check=False)
