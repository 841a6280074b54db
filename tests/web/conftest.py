"""A real hub with simulated devices, its TD directory, and a real headless Chromium.

The browser is Debian's ``chromium`` driven by Playwright (``executable_path``);
``.ci/run`` installs it. If it is missing the tests fail, they never skip: a
twin nobody tested in a browser is not tested.
"""

from __future__ import annotations

import asyncio
import os
import shutil
import tempfile
import threading
from pathlib import Path

import httpx
import pytest

from wott_hub.config import HubConfig
from wott_hub.hub import Hub, demo_devices

CHROMIUM = os.environ.get("WOTT_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
    "--enable-unsafe-swiftshader",  # WebGL on the CPU (plotly's 3D) without a GPU
]


class TwinHub:
    """A hub on 127.0.0.1 (free ports) in its own thread, with a TD directory at ``/things``.

    If the hub does not mount a directory itself, one is mounted here the way the hub will
    (``wott_directory.directory_handlers`` on the hub's HTTP port) and every served TD is
    registered in it, so the pages are tested against the W3C Discovery API.
    """

    def __init__(self, config: HubConfig) -> None:
        self.hub = Hub(config)
        self.directory = None
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)

    def start(self) -> TwinHub:
        self.thread.start()
        self.call(self.hub.start, timeout=60)
        self.url = self.hub.http_url
        if httpx.get(f"{self.url}/things", timeout=10).status_code == 404:
            self.call(self._mount_directory)
        return self

    async def _mount_directory(self) -> None:
        from wott_directory import Directory, DirectorySettings, directory_handlers

        self.directory = Directory(DirectorySettings(base_url=f"{self.url}/"), "sqlite://")
        await self.directory.start()
        self.hub.add_handlers(directory_handlers(self.directory))
        await self.register()

    async def register(self) -> None:
        """(Re-)register every Thing the hub serves."""
        if self.directory is None:
            return
        for thing in list(self.hub.server.things):
            await self.directory.put(thing.td["id"], thing.td)

    def call(self, fn, *args, timeout: float = 30, **kwargs):
        """Run ``fn(*args, **kwargs)`` (a function or coroutine function) on the hub's loop."""
        async def wrapper():
            res = fn(*args, **kwargs)
            if asyncio.iscoroutine(res):
                res = await res
            return res

        return asyncio.run_coroutine_threadsafe(wrapper(), self.loop).result(timeout)

    def stop(self) -> None:
        if self.directory is not None:
            self.call(self.directory.stop)
        self.call(self.hub.stop, timeout=60)
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(10)


def barrel_scene(device_id: str = "barrel", *, loop: bool = True, steps: list[dict] | None = None):
    """A ``scene`` barrel (the TacLink mesh): by default a press and a slide every 1.6 s."""
    from wott_hub.examples import example_device
    from wott_hub.plugins import DeviceConfig

    mesh = example_device("barrel").mesh
    free = mesh.free_indices
    a = [round(float(v), 3) for v in mesh.nodes[free[len(free) // 2]]]
    b = [round(float(v), 3) for v in mesh.nodes[free[len(free) // 3]]]
    steps = steps or [
        {"kind": "press", "at": a, "start_s": 0.1, "duration_s": 0.7, "depth_mm": 3.0, "radius_mm": 14.0},
        {"kind": "slide", "at": b, "to": a, "start_s": 0.9, "duration_s": 0.6, "depth_mm": 2.0,
         "radius_mm": 12.0},
    ]
    return DeviceConfig(device_id, "scene", {"title": f"Barrel skin ({device_id})", "shape": "barrel",
                                             "loop": loop, "rate_hz": 120.0, "step": steps})


@pytest.fixture(scope="package")
def twin(tmp_path_factory):
    """The demo fleet plus a busy scene barrel, history on, a directory at /things."""
    db = tmp_path_factory.mktemp("twin") / "hub.db"
    devices = (*demo_devices(), barrel_scene("barrel"))
    cfg = HubConfig(http_port=0, ws_port=0, database=str(db), ring_size=20_000, history_batch_ms=20,
                    devices=devices)
    hub = TwinHub(cfg).start()
    yield hub
    hub.stop()


@pytest.fixture(scope="package")
def browser():
    """One headless Chromium for the package (a fresh profile), closed at the end."""
    if not Path(CHROMIUM).exists():
        pytest.fail(f"{CHROMIUM} not found: the browser tests need Debian's chromium "
                    "(apt-get install chromium; .ci/run does it)")
    from playwright.sync_api import sync_playwright

    profile = tempfile.mkdtemp(prefix="wott-twin-chromium-")
    with sync_playwright() as p:
        ctx = p.chromium.launch_persistent_context(
            profile, executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True,
            viewport={"width": 1280, "height": 760})
        try:
            yield ctx
        finally:
            ctx.close()
            shutil.rmtree(profile, ignore_errors=True)


@pytest.fixture
def page(browser):
    pg = browser.new_page()
    errors: list[str] = []
    pg.on("pageerror", lambda e: errors.append(str(e)))
    pg.errors = errors
    yield pg
    pg.close()


@pytest.fixture(scope="package")
def shots(tmp_path_factory) -> Path:
    """Where screenshots go: the test's output folder, and WOTT_TWIN_SHOTS (e.g. docs/img) if set."""
    return tmp_path_factory.mktemp("screenshots")


def save_shot(page, shots: Path, name: str) -> Path:
    path = shots / f"{name}.png"
    page.screenshot(path=str(path))
    extra = os.environ.get("WOTT_TWIN_SHOTS")
    if extra:
        Path(extra).mkdir(parents=True, exist_ok=True)
        shutil.copy(path, Path(extra) / f"{name}.png")
    print(f"screenshot: {path}")
    return path


@pytest.fixture(scope="package")
def screenshot(shots):
    return lambda page, name: save_shot(page, shots, name)


@pytest.fixture(scope="package")
def scene_barrel():
    return barrel_scene
