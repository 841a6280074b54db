"""The demo hub, really started, and the foreign WoT clients the interoperability tests drive.

One hub per test module: the demo fleet (each installed plugin's simulated
devices), history on, its TD directory, no mDNS (other hubs on this machine
must not join the fleet under test). Not one for the package: tests/interop has
no ``__init__.py``, so pytest makes no Package node for it and a fixture of scope
"package" lived until the session ended (in the full suite the demo fleet went on
recording behind every later file of that worker). The clients are the ones users have:
node-wot 0.9.2 (npm, pinned by package-lock.json), wotpy 0.18 (the project's
own dependency) and Debian's chromium; the TD validators are the Thingweb
playground's npm packages (pinned there too) and pyld. A missing client fails the suite, it
never skips: ``.ci/run`` installs node and runs ``npm ci`` here; without
node_modules the fixture runs ``npm ci`` itself.
"""

from __future__ import annotations

import asyncio
import json
import queue
import shutil
import subprocess
import tempfile
import threading
import time
from pathlib import Path

import httpx
import pytest

HERE = Path(__file__).resolve().parent
CHROMIUM = "/usr/bin/chromium"
# node-wot and the Thingweb playground's validators, at the versions package.json pins
NODE_PACKAGES: dict[str, str] = json.loads((HERE / "package.json").read_text())["dependencies"]


SLOWER: dict[str, dict[str, float]] = {"flat-vision": {"fps": 10.0}, "barrel-vision": {"fps": 10.0},
                                        "taxel-array": {"rate_hz": 30.0}}
"""The demo fleet's frame rates here, by family: its Things, events and forms are the demo's, fewer
frames a second (the cameras at 30/s and the taxel array at 100/s kept ~0.85 of the 2 cores busy for
as long as the hub ran, ~0.4 at these rates). No test here counts frames or depends on their rate."""


@pytest.fixture(scope="module")
def demo_hub(tmp_path_factory, hub_thread, demo_fleet):
    """A started HubThread (tests/conftest.py) serving the demo fleet on 127.0.0.1, free ports, at the
    frame rates of ``SLOWER``."""
    from wott_hub.config import HubConfig
    from wott_hub.network import DiscoveryConfig

    db = tmp_path_factory.mktemp("interop") / "hub.db"
    cfg = HubConfig.demo_config(http_port=0, ws_port=0, database=str(db), history_batch_ms=20,
                                devices=tuple(demo_fleet(SLOWER)), discovery=DiscoveryConfig.off())
    hub = hub_thread(cfg).start()
    yield hub
    hub.stop()


def _late_press(device_id: str):
    """A scene device that presses once and ends: joining and ending, it makes the hub Thing emit
    ``healthChange`` (which a steady fleet never does), and it presses (``actionDetection``)."""
    from wott_hub.examples import example_device
    from wott_hub.plugins import DeviceConfig

    mesh = example_device("flat").mesh
    at = [round(float(v), 3) for v in mesh.nodes[mesh.free_indices[len(mesh.free_indices) // 2]]]
    return DeviceConfig(device_id, "scene", {"shape": "flat", "loop": False, "rate_hz": 60.0, "step": [
        {"kind": "press", "at": at, "start_s": 0.05, "duration_s": 0.3, "depth_mm": 1.0, "radius_mm": 4.0}]})


async def _press_once(hub, device_id: str) -> None:
    """Add the device; once it has ended and the hub's health watcher (1 s period) has reported
    it, remove it, so that no Thing without events stays in the fleet the next client sees."""
    await hub.add_device(_late_press(device_id))

    async def retire() -> None:
        while hub.devices[device_id].health_state()[0] != "ended":
            await asyncio.sleep(0.1)
        await asyncio.sleep(2.5)
        await hub.remove_device(device_id)

    _RETIRING.add(asyncio.ensure_future(retire()))


_RETIRING: set[asyncio.Future] = set()  # strong references to the retiring tasks


def _tare_every_device(url: str) -> None:
    """Invoke ``tare`` on every device that declares it, over HTTP by its TD's form: each answers
    with a ``deviceAction`` event, which a steady fleet never emits otherwise. Not the scripted
    ``late-`` devices: they retire by themselves, possibly between the listing and the tare."""
    for thing_id in httpx.get(f"{url}/wot").json():
        if thing_id.startswith("late-"):
            continue
        td = httpx.get(f"{url}/wot/{thing_id}").json()
        tare = td.get("actions", {}).get("tare")
        if tare is not None:
            form = tare["forms"][0]
            r = httpx.post(form["href"] if "://" in form["href"] else td["base"] + form["href"], json={})
            assert r.status_code == 200, (thing_id, r.text)


@pytest.fixture(scope="module")
def scripted_press(demo_hub):
    """scripted_press(device_id): a device joins, presses once, ends and leaves (``_late_press``),
    and every device is tared (``_tare_every_device``)."""

    def press(device_id: str) -> None:
        demo_hub.call(_press_once, demo_hub.hub, device_id)
        _tare_every_device(demo_hub.url)

    return press


@pytest.fixture(scope="module")
def tare_every_device(demo_hub):
    """tare_every_device(): every device tared now (``_tare_every_device``), and recorded: returns once
    the hub's history has nothing queued, so that a replay started next holds the ``deviceAction``."""

    def tare() -> None:
        _tare_every_device(demo_hub.url)
        poll(lambda: httpx.get(f"{demo_hub.url}/wot/hub/properties/eventCounters").json()["history"].get(
            "queued", 0) == 0, 10, "the tares recorded")

    return tare


def poll(predicate, timeout: float, what: str) -> None:
    """Wait for ``predicate()`` without an event loop (Playwright's sync API may be running one)."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"{what}: not met within {timeout} s")
        time.sleep(0.1)


@pytest.fixture(scope="module")
def fleet(demo_hub):
    """The demo hub once no scripted device of an earlier module is left (they retire by themselves)
    and every device has recorded a press (so a replay started now has one to replay)."""
    def settled() -> bool:
        with httpx.Client(base_url=demo_hub.url, timeout=5) as c:
            if any(i.startswith("late-") for i in c.get("/wot").json()):
                return False
            things = c.get("/wot/hub/properties/eventCounters").json()["things"]
        return all(t["byName"].get("actionDetection", 0) > 0 for k, t in things.items() if k != "hub")

    poll(settled, 30, "every demo device pressed, no scripted device of an earlier test left")
    return demo_hub


@pytest.fixture(scope="session")
def node_wot() -> list[str]:
    """The command running node with node-wot 0.9.2 and the playground's validators installed beside
    it (tests/interop/node_modules, from package-lock.json)."""
    node = shutil.which("node") or shutil.which("nodejs")
    if node is None:
        pytest.fail("node not found: the interop tests drive node-wot (apt-get install nodejs npm; "
                    ".ci/run does it)")
    if not all((HERE / "node_modules" / pkg / "package.json").exists() for pkg in NODE_PACKAGES):
        npm = shutil.which("npm")
        if npm is None:
            pytest.fail("node-wot is not installed in tests/interop and npm is missing (apt-get install npm)")
        done = subprocess.run([npm, "ci", "--no-audit", "--no-fund"], cwd=HERE, capture_output=True,
                              text=True, timeout=300)
        if done.returncode != 0:
            pytest.fail(f"npm ci in tests/interop failed:\n{done.stderr[-2000:]}")
    for pkg, pinned in NODE_PACKAGES.items():
        version = json.loads((HERE / "node_modules" / pkg / "package.json").read_text())["version"]
        assert version == pinned, f"{pkg} {version} installed, the lockfile pins {pinned}"
    return [node]


class NodeScript:
    """A node script run against the hub: JSON lines on stdout, taken one at a time."""

    def __init__(self, cmd: list[str]) -> None:
        self.proc = subprocess.Popen(cmd, cwd=HERE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True)
        self.lines: queue.Queue[str | None] = queue.Queue()
        self.stderr: list[str] = []
        threading.Thread(target=self._pump, args=(self.proc.stdout, self.lines.put), daemon=True).start()
        threading.Thread(target=self._pump, args=(self.proc.stderr, self.stderr.append), daemon=True).start()

    @staticmethod
    def _pump(stream, put) -> None:
        for line in stream:
            put(line)
        put(None)

    def next(self, timeout: float) -> dict:
        """The next JSON line; fails with the script's stderr if it ends or stalls first."""
        try:
            line = self.lines.get(timeout=timeout)
        except queue.Empty:
            line = None
        if line is None:
            self.proc.kill()
            raise AssertionError(f"node script ended or stalled (>{timeout} s) without output:\n"
                                 f"{_tail(''.join(x for x in self.stderr if x))}")
        return json.loads(line)

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait(10)


def _tail(err: str) -> str:
    # node-wot warns about every unknown format in its TD schema; keep what matters
    return "\n".join(x for x in err.splitlines() if "unknown format" not in x)[-3000:]


@pytest.fixture(scope="module")
def node_script(node_wot):
    """node_script(name, *args) -> a running NodeScript (tests/interop/<name>), killed at the end."""
    started: list[NodeScript] = []

    def start(name: str, *args: str) -> NodeScript:
        s = NodeScript([*node_wot, str(HERE / name), *args])
        started.append(s)
        return s

    yield start
    for s in started:
        s.close()


@pytest.fixture(scope="module")
def browser():
    """Debian's chromium, headless, driven by Playwright (as tests/web does). Module-scoped: the
    sync API runs an event loop in this thread while open, which ``asyncio.run`` elsewhere refuses."""
    if not Path(CHROMIUM).exists():
        pytest.fail(f"{CHROMIUM} not found: the browser interop test needs Debian's chromium "
                    "(apt-get install chromium; .ci/run does it)")
    from playwright.sync_api import sync_playwright

    profile = tempfile.mkdtemp(prefix="wott-interop-chromium-")
    with sync_playwright() as p:
        ctx = p.chromium.launch_persistent_context(
            profile, executable_path=CHROMIUM, headless=True,
            args=["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync"])
        try:
            yield ctx
        finally:
            ctx.close()
            shutil.rmtree(profile, ignore_errors=True)
