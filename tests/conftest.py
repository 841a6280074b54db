"""Shared fixtures: where the read-only reference data lives, waiting and running coroutines, a hub in
its own thread, reading SSE streams and a simple pressing scene device."""

from __future__ import annotations

import asyncio
import inspect
import os
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = ROOT.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    if not SHARED_DATA.exists():
        pytest.fail(f"reference data not found at {SHARED_DATA} (../shared beside the checkout)")
    return SHARED_DATA


async def _wait_for(predicate, timeout: float = 15.0, what: Any = "condition", every: float = 0.05) -> None:
    """Poll ``predicate`` (sync or async) until true; fail naming ``what`` (a string, or a callable
    giving one at the time of failure) after ``timeout`` s."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while True:
        ok = predicate()
        if inspect.isawaitable(ok):
            ok = await ok
        if ok:
            return
        if loop.time() > deadline:
            raise AssertionError(f"{what() if callable(what) else what}: not met within {timeout} s")
        await asyncio.sleep(every)


@pytest.fixture(scope="session")
def wait_for():
    """``await wait_for(predicate, timeout=..., what=...)`` inside a test's event loop."""
    return _wait_for


def _eventually(predicate, timeout: float = 15.0, what: Any = "condition", every: float = 0.05) -> Any:
    """Poll ``predicate`` from a plain (thread) test until it gives a true value, and return it; fail
    naming ``what`` after ``timeout`` s. A test waits for what it asserts, never for a fixed sleep: a
    hub started by the test's own module has had no time to commit, publish or count anything yet."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"{what() if callable(what) else what}: not met within {timeout} s")
        time.sleep(every)


@pytest.fixture(scope="session")
def eventually():
    """``eventually(predicate, timeout=..., what=...)`` -> the predicate's first true value."""
    return _eventually


def _run(coro: Any, timeout: float = 60) -> Any:
    """Run ``coro`` in a fresh event loop, failing (TimeoutError) after ``timeout`` s."""
    return asyncio.run(asyncio.wait_for(coro, timeout))


@pytest.fixture(scope="session")
def run():
    """``run(coro, timeout=60)``: a test's scenario in its own event loop, with an overall time limit."""
    return _run


class HubThread:
    """A real hub on 127.0.0.1 (free ports) running in its own thread and event loop."""

    def __init__(self, config) -> None:
        from wott_hub.hub import Hub  # imported when a test needs a hub, not at collection

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

    @property
    def url(self) -> str:
        """The hub's HTTP base URL (no trailing slash)."""
        return self.hub.http_url

    def call(self, fn, *args, timeout: float = 30, **kwargs):
        """Run ``fn(*args, **kwargs)`` (a function or coroutine function) on the hub's loop."""
        async def wrapper():
            res = fn(*args, **kwargs)
            if asyncio.iscoroutine(res):
                res = await res
            return res

        return asyncio.run_coroutine_threadsafe(wrapper(), self.loop).result(timeout)

    def stop(self) -> None:
        if self.thread.is_alive():
            asyncio.run_coroutine_threadsafe(self.hub.stop(), self.loop).result(60)
            self.loop.call_soon_threadsafe(self.loop.stop)
            self.thread.join(10)


@pytest.fixture(scope="session")
def hub_thread():
    """The HubThread class (test modules cannot import conftest under importlib mode)."""
    return HubThread


def _sse_events(url: str, n: int, headers: dict[str, str] | None = None, timeout: float = 15,
                assert_content_type: bool = False) -> list:
    """The first ``n`` events (httpx_sse ``ServerSentEvent``) of the SSE stream at ``url``.
    ``assert_content_type`` also asserts the response's Content-Type starts with
    ``text/event-stream`` (httpx_sse itself only checks that it contains it)."""
    import httpx
    from httpx_sse import connect_sse

    out = []
    with httpx.Client(timeout=timeout) as c, connect_sse(c, "GET", url, headers=headers or {}) as es:
        if assert_content_type:
            assert es.response.headers["content-type"].startswith("text/event-stream")
        for ev in es.iter_sse():
            out.append(ev)
            if len(out) >= n:
                break
    return out


@pytest.fixture(scope="session")
def sse_events():
    """``sse_events(url, n, headers=None, timeout=15, assert_content_type=False)`` -> the first n
    ``ServerSentEvent`` (``.id``, ``.event``, ``.data``) of a stream."""
    return _sse_events


def _press_scene(device_id: str, shape: str = "flat", start_s: float = 0.1):
    """A ``scene`` device pressing its skin now and then: a 0.3 s press from ``start_s``, looped
    (cheap: flat and cylinder skins)."""
    from wott_hub.examples import example_device
    from wott_hub.plugins import DeviceConfig

    mesh = example_device(shape).mesh
    at = [round(float(v), 3) for v in mesh.nodes[mesh.free_indices[len(mesh.free_indices) // 2]]]
    return DeviceConfig(device_id, "scene", {"shape": shape, "loop": True, "rate_hz": 60.0, "step": [
        {"kind": "press", "at": at, "start_s": start_s, "duration_s": 0.3, "depth_mm": 1.0,
         "radius_mm": 4.0}]})


@pytest.fixture(scope="session")
def press_scene():
    """press_scene(device_id, shape="flat", start_s=0.1) -> DeviceConfig."""
    return _press_scene


def _demo_fleet(rates: dict[str, dict[str, float]]) -> list:
    """The demo fleet (each installed plugin's simulated devices), each family's settings overridden by
    ``rates`` (fewer frames a second where a test counts none: the demo's own rates keep a core busy)."""
    import dataclasses

    from wott_hub.plugins.demo import demo_devices

    return [dataclasses.replace(d, settings={**d.settings, **rates.get(d.family, {})})
            for d in demo_devices()]


@pytest.fixture(scope="session")
def demo_fleet():
    """demo_fleet(rates) -> the demo's DeviceConfigs at those rates (``_demo_fleet``)."""
    return _demo_fleet


# --- the wott-hub command as a person runs it (tests/cli, tests/adversarial) ---------------------

WOTT_HUB = str(Path(sys.executable).with_name("wott-hub"))


def _cli(*args: str, cwd: Path | str | None = None, env: dict[str, str] | None = None,
         input: str | None = None, timeout: float = 120,
         columns: int = 80) -> subprocess.CompletedProcess[str]:
    full_env = {**os.environ, "COLUMNS": str(columns), **(env or {})}
    return subprocess.run([WOTT_HUB, *args], capture_output=True, text=True, timeout=timeout, cwd=cwd,
                          env=full_env, input=input)


@pytest.fixture(scope="session")
def cli():
    """``cli(*args, cwd=None, env=None, input=None, timeout=120, columns=80)`` -> CompletedProcess."""
    return _cli


def one_error(res: subprocess.CompletedProcess[str], code: int) -> str:
    """The one ``error:`` line of a command that failed with ``code``, and no traceback."""
    assert res.returncode == code, (res.returncode, res.stdout, res.stderr)
    assert "Traceback" not in res.stderr + res.stdout, res.stderr
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), res.stderr
    return lines[0]


@pytest.fixture(scope="session")
def one_error_line():
    """``one_error_line(process, code)`` -> the single ``error: ...`` line it printed."""
    return one_error
