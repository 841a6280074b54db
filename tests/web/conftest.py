"""A real hub with simulated devices, its own TD directory, and a real headless Chromium.

The browser is Debian's ``chromium`` driven by Playwright (``executable_path``);
``.ci/run`` installs it. If it is missing the tests fail, they never skip: a
twin nobody tested in a browser is not tested.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest

from wott_hub.config import HubConfig
from wott_hub.network import DirectoryConfig

CHROMIUM = os.environ.get("WOTT_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
    "--enable-unsafe-swiftshader",  # WebGL on the CPU (the device page's three.js) without a GPU
]


def barrel_scene(device_id: str = "barrel", *, loop: bool = True, steps: list[dict] | None = None):
    """A ``scene`` barrel (the TacLink mesh): by default a press then a slide every 1.6 s, on the
    side the device page's camera looks at."""
    from wott_hub.examples import example_device
    from wott_hub.plugins import DeviceConfig

    mesh = example_device("barrel").mesh
    free = mesh.free_indices
    p = mesh.nodes[free]
    mid = (p[:, 2].min() + p[:, 2].max()) / 2
    facing = p[:, 0] - p[:, 1]  # the camera's eye is at +x, -y

    def at(z: float) -> list[float]:
        k = int(np.argmax(facing - 2 * np.abs(p[:, 2] - z)))
        return [round(float(v), 3) for v in p[k]]

    steps = steps or [
        {"kind": "press", "at": at(mid), "start_s": 0.1, "duration_s": 0.7, "depth_mm": 4.0,
         "radius_mm": 25.0},
        {"kind": "slide", "at": at(mid + 50), "to": at(mid), "start_s": 0.9, "duration_s": 0.6,
         "depth_mm": 2.5, "radius_mm": 18.0},
    ]
    return DeviceConfig(device_id, "scene", {"title": f"Barrel skin ({device_id})", "shape": "barrel",
                                             "loop": loop, "rate_hz": 120.0, "step": steps})


@pytest.fixture(scope="package")
def hub_runner(hub_thread):
    """start_hub(db, devices, directory=True) -> a started HubThread (tests/conftest.py) with history.
    Its own TD directory is at ``/things`` (every Thing it serves is registered there as it is exposed,
    deleted as it is removed), so the pages are tested against the W3C Discovery API;
    ``directory=False`` turns it off."""

    def start_hub(db: Path, devices, *, directory: bool = True):
        cfg = HubConfig(http_port=0, ws_port=0, database=str(db), ring_size=20_000, history_batch_ms=20,
                        devices=tuple(devices), directory=DirectoryConfig(enabled=directory))
        return hub_thread(cfg).start()

    return start_hub


@pytest.fixture(scope="package")
def twin(tmp_path_factory, hub_runner):
    """A hub with one busy scene barrel, history on, a directory at /things."""
    hub = hub_runner(tmp_path_factory.mktemp("twin") / "hub.db", [barrel_scene("barrel")])
    yield hub
    hub.stop()


# The demo devices' frame rates in ``fleet``: what its pages show (the list, a camera's live image) needs
# a few frames a second; at the demo's own (cameras 30 fps, taxels 100 Hz) the fleet took ~0.5-0.7
# of a core while the browser waited for it.
FLEET_RATES = {"barrel-vision": {"fps": 5.0}, "flat-vision": {"fps": 5.0}, "taxel-array": {"rate_hz": 10.0}}


@pytest.fixture(scope="module")
def fleet(tmp_path_factory, hub_runner, demo_fleet):
    """The demo fleet (each installed plugin's simulated devices, at the rates of ``FLEET_RATES``) and
    the scene barrel."""
    devices = [*demo_fleet(FLEET_RATES), barrel_scene("barrel")]
    hub = hub_runner(tmp_path_factory.mktemp("fleet") / "hub.db", devices)
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


def new_page(browser):
    pg = browser.new_page()
    errors: list[str] = []
    pg.on("pageerror", lambda e: errors.append(str(e)))
    pg.errors = errors
    return pg


@pytest.fixture
def page(browser):
    pg = new_page(browser)
    yield pg
    pg.close()


def wait_until(page, expression: str, timeout: float = 15_000, arg=None):
    """page.wait_for_function, failing with the page's state (``window.twin``) on timeout."""
    from playwright.sync_api import TimeoutError as PlaywrightTimeout

    try:
        return page.wait_for_function(expression, arg=arg, timeout=timeout)
    except PlaywrightTimeout:
        state = page.evaluate("(() => { try { const t = {...window.twin};"
                              " if (t.seqs) t.seqs = t.seqs.length;"
                              " return JSON.stringify(t).slice(0, 4000); }"
                              " catch (e) { return String(e); } })()")
        raise AssertionError(f"timed out after {timeout} ms waiting for {expression}\n"
                             f"page errors: {getattr(page, 'errors', [])}\nwindow.twin: {state}") from None


@pytest.fixture(scope="package")
def wait():
    return wait_until


@pytest.fixture(scope="package")
def shots(tmp_path_factory) -> Path:
    """Where screenshots go: the test's output folder, and WOTT_TWIN_SHOTS (e.g. docs/img) if set."""
    return tmp_path_factory.mktemp("screenshots")


def save_shot(page, shots: Path, name: str, **options) -> Path:
    path = shots / f"{name}.png"
    page.screenshot(path=str(path), **options)
    extra = os.environ.get("WOTT_TWIN_SHOTS")
    if extra:
        Path(extra).mkdir(parents=True, exist_ok=True)
        shutil.copy(path, Path(extra) / f"{name}.png")
    print(f"screenshot: {path}")
    return path


@pytest.fixture(scope="package")
def screenshot(shots):
    return lambda page, name, **options: save_shot(page, shots, name, **options)


@pytest.fixture(scope="package")
def scene_barrel():
    return barrel_scene


@pytest.fixture(scope="package")
def open_page():
    """new_page(browser) for module-scoped pages (test modules cannot import conftest)."""
    return new_page
