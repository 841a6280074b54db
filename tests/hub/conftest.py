from __future__ import annotations

import asyncio
import threading

import pytest

from wott_hub.config import HubConfig
from wott_hub.hub import Hub


class HubThread:
    """A real hub on 127.0.0.1 (free ports) running in its own thread and event loop."""

    def __init__(self, config: HubConfig) -> None:
        self.hub = Hub(config)
        self.loop = asyncio.new_event_loop()
        self._started = threading.Event()
        self._error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        asyncio.set_event_loop(self.loop)
        try:
            self.loop.run_until_complete(self.hub.start())
        except BaseException as e:  # surfaced to the test
            self._error = e
            self._started.set()
            return
        self._started.set()
        self.loop.run_forever()

    def start(self) -> HubThread:
        self.thread.start()
        self._started.wait(60)
        if self._error is not None:
            raise self._error
        return self

    def call(self, fn, *args, timeout: float = 30):
        """Run ``fn(*args)`` (a function or coroutine function) on the hub's loop."""
        async def wrapper():
            res = fn(*args)
            if asyncio.iscoroutine(res):
                res = await res
            return res

        return asyncio.run_coroutine_threadsafe(wrapper(), self.loop).result(timeout)

    def stop(self) -> None:
        if self.thread.is_alive():
            asyncio.run_coroutine_threadsafe(self.hub.stop(), self.loop).result(60)
            self.loop.call_soon_threadsafe(self.loop.stop)
            self.thread.join(10)


def scene_device(device_id: str, shape: str, rate_hz: float = 120.0):
    """A ``scene``-family DeviceConfig touching its skin almost all the time (a busy stream)."""
    from wott_hub.examples import example_device
    from wott_hub.plugins import DeviceConfig

    mesh = example_device(shape).mesh
    free = mesh.free_indices
    a = [float(v) for v in mesh.nodes[free[len(free) // 2]]]
    b = [float(v) for v in mesh.nodes[free[len(free) // 3]]]
    radius = 12.0 if shape == "barrel" else 4.0
    return DeviceConfig(device_id, "scene", {
        "shape": shape, "loop": True, "rate_hz": rate_hz, "step": [
            {"kind": "press", "at": a, "start_s": 0.0, "duration_s": 0.6, "depth_mm": 2.0,
             "radius_mm": radius},
            {"kind": "slide", "at": b, "to": a, "start_s": 0.7, "duration_s": 0.6, "depth_mm": 1.5,
             "radius_mm": radius},
        ]})


@pytest.fixture
def hub_factory(tmp_path):
    started: list[HubThread] = []

    def make(**overrides) -> HubThread:
        cfg = HubConfig(http_port=0, ws_port=0, database=str(tmp_path / "hub.db"), **overrides)
        ht = HubThread(cfg).start()
        started.append(ht)
        return ht

    yield make
    for ht in started:
        ht.stop()


@pytest.fixture(scope="session")
def hub_thread():
    """The HubThread class (test modules cannot import conftest under importlib mode)."""
    return HubThread


@pytest.fixture(scope="session")
def scene():
    return scene_device
