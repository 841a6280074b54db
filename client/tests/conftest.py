"""A live hub for the client's tests, started as the hub's own suite starts one (tests/conftest.py).

One hub for the session: two pressing scene devices (a flat pad and a cylinder) on
127.0.0.1, its directory on, no mDNS (the mDNS test uses a device that announces itself).
The hub suite's helpers are loaded from its conftest by path: under importlib mode a
conftest cannot be imported by name, and copying HubThread would let the two drift.
"""

from __future__ import annotations

import asyncio
import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _load(name: str, path: Path):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


HELPERS = _load("wott_hub_test_helpers", ROOT / "tests" / "conftest.py")
DISCOVERY = _load("wott_hub_discovery_helpers", ROOT / "tests" / "discovery" / "conftest.py")


@pytest.fixture(scope="session")
def run():
    return HELPERS._run


@pytest.fixture(scope="session")
def wait_for():
    return HELPERS._wait_for


@pytest.fixture(scope="module")
def hub():
    """A started HubThread: devices ``pad`` (flat) and ``cyl`` (cylinder), pressing in a loop."""
    from wott_hub.config import HubConfig
    from wott_hub.network import DiscoveryConfig

    cfg = HubConfig(http_port=0, ws_port=0, history=False, discovery=DiscoveryConfig.off(),
                    devices=(HELPERS._press_scene("pad"), HELPERS._press_scene("cyl", "cylinder")))
    h = HELPERS.HubThread(cfg).start()
    yield h
    h.stop()


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A started HubThread with history: ``pad`` pressing, ``cam`` a simulated camera pad (10 frames/s)
    and ``grid`` a simulated taxel array (issue 29: raw frames, history ranges, actions)."""
    from wott_hub.config import HubConfig
    from wott_hub.network import DiscoveryConfig
    from wott_hub.plugins import DeviceConfig

    cfg = HubConfig(http_port=0, ws_port=0, database=str(tmp_path_factory.mktemp("fields") / "hub.db"),
                    history_batch_ms=20, discovery=DiscoveryConfig.off(), devices=(
                        HELPERS._press_scene("pad"),
                        DeviceConfig("cam", "flat-vision", {"source": "sim", "fps": 10.0}),
                        DeviceConfig("grid", "taxel-array", {"simulate": True, "rate_hz": 30.0})))
    h = HELPERS.HubThread(cfg).start()
    yield h
    h.stop()


@pytest.fixture(scope="session")
def eventually():
    return HELPERS._eventually


@pytest.fixture(scope="session")
def device_sim():
    """``sim = await device_sim(name).start()`` ... ``await sim.stop()`` in the test's event loop:
    tests/discovery's simulator (another server's Tactile TD, its SSE stream with named messages
    and ids in µs, ``POST /press`` and ``POST /outage``, announced on mDNS)."""
    return lambda name: DISCOVERY.Sim("127.0.0.1", name=name, thing_id=f"urn:example:{name}")


class Proxy:
    """A TCP relay on 127.0.0.1 that the test can cut: ``drop(pause_s)`` closes every relayed
    connection and refuses new ones for ``pause_s``, as a network outage would."""

    def __init__(self, host: str, port: int) -> None:
        self.target = (host, port)
        self.writers: set[asyncio.StreamWriter] = set()
        self.refuse_until = 0.0
        self.server: asyncio.Server | None = None
        self.drops = 0

    @property
    def port(self) -> int:
        return self.server.sockets[0].getsockname()[1]

    async def start(self) -> Proxy:
        self.server = await asyncio.start_server(self._serve, "127.0.0.1", 0)
        return self

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        loop = asyncio.get_running_loop()
        if loop.time() < self.refuse_until:
            writer.close()
            return
        try:
            up_reader, up_writer = await asyncio.open_connection(*self.target)
        except OSError:
            writer.close()
            return
        self.writers |= {writer, up_writer}

        async def pipe(src: asyncio.StreamReader, dst: asyncio.StreamWriter) -> None:
            try:
                while data := await src.read(65536):
                    dst.write(data)
                    await dst.drain()
            except (ConnectionError, OSError):
                pass
            finally:
                dst.close()

        try:
            await asyncio.gather(pipe(reader, up_writer), pipe(up_reader, writer))
        except asyncio.CancelledError:  # the test's loop is ending
            pass
        finally:
            self.writers -= {writer, up_writer}

    def drop(self, pause_s: float = 0.5) -> None:
        self.drops += 1
        self.refuse_until = asyncio.get_running_loop().time() + pause_s
        for w in list(self.writers):
            w.transport.abort()
        self.writers.clear()

    async def stop(self) -> None:
        self.drop(0)
        self.server.close()
        await self.server.wait_closed()


@pytest.fixture(scope="session")
def proxy():
    """The Proxy class: ``p = await proxy(host, port).start()`` in the test's event loop."""
    return Proxy
