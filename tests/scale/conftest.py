"""A real Mosquitto broker on 127.0.0.1 for the MQTT and fleet tests, and an MQTT reader.

Debian's ``mosquitto`` package (installed by ``.ci/run``); without it the tests fail
naming the package, never skip. Each broker gets a free port and a minimal config
(``listener <port> 127.0.0.1``, ``allow_anonymous true``, no persistence: a restart
loses every retained message, which is what the hub must survive).
"""

from __future__ import annotations

import asyncio
import json
import shutil
import socket
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

MISSING = ("mosquitto not found (PATH or /usr/sbin): .ci/run installs it (apt-get install mosquitto); "
           "the MQTT tests need a real broker")


def mosquitto_binary() -> str:
    found = shutil.which("mosquitto") or next(
        (p for p in ("/usr/sbin/mosquitto", "/usr/local/sbin/mosquitto") if Path(p).exists()), None)
    if found is None:
        pytest.fail(MISSING, pytrace=False)
    return found


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Broker:
    """One Mosquitto process; ``restart`` brings it back on the same port (retained messages lost)."""

    def __init__(self, folder: Path) -> None:
        self.binary = mosquitto_binary()
        self.port = free_port()
        self.conf = folder / "mosquitto.conf"
        self.conf.write_text(f"listener {self.port} 127.0.0.1\nallow_anonymous true\npersistence false\n"
                             f"set_tcp_nodelay true\n")
        self.log = folder / "mosquitto.log"
        self.proc: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"mqtt://127.0.0.1:{self.port}"

    def start(self) -> Broker:
        with self.log.open("ab") as log:
            self.proc = subprocess.Popen([self.binary, "-c", str(self.conf)], stdout=log, stderr=log)
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"mosquitto exited: {self.log.read_text()[-2000:]}")
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", self.port)) == 0:
                    return self
            time.sleep(0.05)
        raise RuntimeError(f"mosquitto did not listen on {self.port}: {self.log.read_text()[-2000:]}")

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.proc = None

    def restart(self) -> None:
        self.stop()
        self.start()


@pytest.fixture
def broker(tmp_path) -> Iterator[Broker]:
    b = Broker(tmp_path).start()
    yield b
    b.stop()


class MqttReader:
    """A plain MQTT client (aiomqtt) collecting every message of its subscriptions in a task."""

    def __init__(self, broker_url: str, *filters: str) -> None:
        host, _, port = broker_url.removeprefix("mqtt://").partition(":")
        self.host, self.port = host, int(port or 1883)
        self.filters = filters
        self.messages: list[tuple[str, bytes, bool]] = []  # topic, payload, retain
        self._task: asyncio.Task[None] | None = None
        self._ready = asyncio.Event()

    async def __aenter__(self) -> MqttReader:
        self._task = asyncio.create_task(self._run())
        await asyncio.wait_for(self._ready.wait(), 10)
        return self

    async def __aexit__(self, *exc: object) -> None:
        assert self._task is not None
        self._task.cancel()
        try:
            await self._task
        except asyncio.CancelledError:
            pass

    async def _run(self) -> None:
        import aiomqtt

        async with aiomqtt.Client(self.host, self.port) as client:
            for f in self.filters:
                await client.subscribe(f, qos=1)
            self._ready.set()
            async for msg in client.messages:
                payload = msg.payload if isinstance(msg.payload, bytes) else str(msg.payload).encode()
                self.messages.append((str(msg.topic), payload, bool(msg.retain)))

    def on(self, topic: str) -> list[Any]:
        """The decoded JSON payloads received on ``topic`` (empty payloads skipped)."""
        return [json.loads(p) for t, p, _ in self.messages if t == topic and p]

    def topics(self) -> set[str]:
        return {t for t, _, _ in self.messages}


@pytest.fixture(scope="session")
def mqtt_reader():
    """``MqttReader(broker_url, *filters)``: ``async with`` it; ``.messages``, ``.on(topic)``."""
    return MqttReader


@pytest.fixture(scope="session")
def broker_class():
    return Broker
