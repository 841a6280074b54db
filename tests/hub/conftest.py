from __future__ import annotations

import threading

import httpx
import pytest


class SSE:
    """Every event of an SSE stream, read in a thread until ``stop()``: (id, event, data)."""

    def __init__(self, url: str) -> None:
        self.got: list[tuple[int, str, str]] = []
        self.error: BaseException | None = None
        self.connected = threading.Event()
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run, args=(url,), daemon=True)
        self.thread.start()
        assert self.connected.wait(10), "SSE stream did not connect"

    def _run(self, url: str) -> None:
        from httpx_sse import connect_sse

        try:
            with httpx.Client(timeout=20) as c, connect_sse(c, "GET", url) as es:
                self.connected.set()
                for ev in es.iter_sse():
                    self.got.append((int(ev.id), ev.event, ev.data))
                    if self._stop.is_set():
                        return
        except BaseException as e:  # surfaced by stop()
            self.error = e
            self.connected.set()

    def stop(self) -> list[tuple[int, str, str]]:
        self._stop.set()
        self.thread.join(20)
        assert self.error is None, f"the SSE stream failed: {self.error!r}"
        assert not self.thread.is_alive(), "the SSE stream stopped delivering"
        return self.got


@pytest.fixture
def sse():
    """``sse(url)``: an ``SSE`` reader of ``url`` (a device's or the hub's event stream)."""
    return SSE


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


@pytest.fixture(scope="session")
def scene():
    return scene_device
