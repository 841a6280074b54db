"""Issue 16 item 2 (and item 10's unreported plugins): a plugin's failure marks its device only.

Real plugins, installed the way pip installs one (a ``.dist-info`` with an
entry point on ``sys.path``, as tests/plugins/conftest.py does), loaded by the
process's real registry, serve devices in a real hub (``HubThread``): a driver
whose ``health()`` raises, whose ``prepare()`` raises, whose ``close()``
raises, whose ``frames()`` raises after a few frames, a plugin whose open hook
raises, a plugin whose hooks raise, and a plugin that cannot even be imported.
Through all of it the hub Thing's properties answer 200 with the devices
marked, a healthy device keeps streaming with no gap (SSE ids against
history), and the health watcher still publishes ``healthChange`` over SSE.
The same plugin also runs in a worker process (``[hub] workers``).
"""

from __future__ import annotations

import json
import logging
import sys
import textwrap
import threading
import time
from pathlib import Path

import httpx
import pytest

from wott_hub.config import HubConfig
from wott_hub.events.record import KIND_EVENT
from wott_hub.plugins import ENTRY_POINT_GROUP, DeviceConfig, get_registry, reset_registry

FAULTY = '''
import asyncio
import time

import numpy as np

from wott_hub.examples import example_device
from wott_hub.plugin_api import Driver, FamilyInfo, TactileFrame, hookimpl


class FaultyDriver(Driver):
    """Rest frames at 50 Hz; ``fail`` names the call that raises."""

    def __init__(self, description, fail, after):
        super().__init__(description)
        self.fail, self.after = fail, after

    async def prepare(self):
        if self.fail == "prepare":
            raise ZeroDivisionError("prepare exploded")

    async def frames(self):
        n = self.description.mesh.n_nodes
        for k in range(1, 1 << 30):
            await asyncio.sleep(0.02)
            if self.fail == "frames" and k > self.after:
                raise RuntimeError(f"frames exploded after {self.after}")
            yield TactileFrame(time.time_ns(), np.zeros((n, 3)))

    def health(self):
        if self.fail == "health":
            raise ValueError("health exploded")
        return super().health()

    async def close(self):
        if self.fail == "close":
            raise OSError("close exploded")


@hookimpl
def wott_hub_families():
    schema = {"type": "object", "additionalProperties": False,
              "properties": {"fail": {"enum": ["none", "open", "prepare", "frames", "health", "close"],
                                      "default": "none"},
                             "after": {"type": "integer", "minimum": 0, "default": 3}}}
    return [FamilyInfo("faulty", "A driver that raises where it is told to.", schema)]


@hookimpl
def wott_hub_open_device(config):
    if config.settings["fail"] == "open":
        raise KeyError("no such camera")
    return FaultyDriver(example_device("flat", config.id), config.settings["fail"], config.settings["after"])
'''

HOOKBOMB = '''
from wott_hub.plugin_api import hookimpl


@hookimpl
def wott_hub_families():
    raise RuntimeError("families exploded")


@hookimpl
def wott_hub_claim_td(td):
    raise RuntimeError("claim_td exploded")


@hookimpl
def wott_hub_demo_devices():
    raise SystemExit(3)
'''

UNLOADABLE = '''
import wott_no_such_dependency  # noqa: F401
'''

PLUGINS = {"faulty": FAULTY, "hookbomb": HOOKBOMB, "unloadable": UNLOADABLE}


def write_site(root: Path) -> Path:
    for name, source in PLUGINS.items():
        (root / f"wott_test_{name}.py").write_text(textwrap.dedent(source))
        info = root / f"wott_test_{name}-1.0.dist-info"
        info.mkdir()
        (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: wott-test-{name}\nVersion: 1.0\n")
        (info / "entry_points.txt").write_text(f"[{ENTRY_POINT_GROUP}]\n{name} = wott_test_{name}\n")
    return root


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """The three plugins installed (on sys.path, PYTHONPATH for processes), and only they selected."""
    root = write_site(tmp_path_factory.mktemp("site"))
    with pytest.MonkeyPatch.context() as mp:
        mp.syspath_prepend(str(root))
        mp.setenv("PYTHONPATH", str(root))
        mp.setenv("WOTT_HUB_PLUGINS", ",".join(PLUGINS))
        reset_registry()
        yield root
        reset_registry()
    for name in PLUGINS:
        sys.modules.pop(f"wott_test_{name}", None)


def faulty(device_id: str, fail: str, after: int = 3) -> DeviceConfig:
    return DeviceConfig(device_id, "faulty", {"fail": fail, "after": after})


DEVICES = {"ok-1": "none", "ctl": "none", "bad-health": "health", "bad-frames": "frames",
           "bad-close": "close", "bad-prepare": "prepare", "bad-open": "open"}


@pytest.fixture(scope="module")
def hub(site, tmp_path_factory, hub_thread, press_scene):
    cfg = HubConfig(http_port=0, ws_port=0, database=str(tmp_path_factory.mktemp("db") / "hub.db"),
                    devices=(press_scene("pad"), *(faulty(i, f) for i, f in DEVICES.items())))
    ht = hub_thread(cfg).start()
    yield ht
    ht.stop()


CLIENT = httpx.Client(timeout=10)  # one keep-alive connection per hub: the reads stay cheap


def get(hub, path: str) -> httpx.Response:
    r = CLIENT.get(f"{hub.url}{path}")
    assert r.status_code == 200, (path, r.status_code, r.text[:300])
    return r


def until(predicate, what: str, timeout_s: float = 10.0):
    deadline = time.monotonic() + timeout_s
    while True:
        value = predicate()
        if value:
            return value
        assert time.monotonic() < deadline, f"{what}: not within {timeout_s} s"
        time.sleep(0.05)


def test_hub_properties_answer_with_each_faulty_device_marked(hub, caplog):
    caplog.set_level(logging.WARNING)

    def counted() -> dict | None:  # the module's first test: read once its first frame is counted
        health = get(hub, "/wot/hub/properties/health").json()
        return health if health["devices"]["bad-health"]["frames"] > 0 else None

    health = until(counted, "bad-health's frames counted")  # its frames flow: only its health is broken
    devices = health["devices"]
    assert devices["pad"]["state"] == "ok" and devices["ok-1"]["state"] == "ok"
    assert devices["bad-health"] == {**devices["bad-health"], "state": "degraded",
                                     "reason": "health() raised ValueError: health exploded"}
    assert devices["bad-prepare"]["state"] == "failed"
    assert "prepare() raised ZeroDivisionError: prepare exploded" in devices["bad-prepare"]["reason"]
    assert devices["bad-open"]["state"] == "failed"
    assert "plugin 'faulty' raised KeyError: 'no such camera'" in devices["bad-open"]["reason"]
    assert health["state"] == "degraded"
    listed = {d["id"]: d["state"] for d in get(hub, "/wot/hub/properties/devices").json()}
    assert listed["bad-health"] == "degraded" and listed["pad"] == "ok"
    assert "bad-prepare" not in listed and "bad-open" not in listed  # never served
    get(hub, "/wot/hub/properties/eventCounters")
    for _ in range(20):  # reading it again and again does not log it again and again
        get(hub, "/wot/hub/properties/health")
    assert len([r for r in caplog.records if "health exploded" in r.getMessage()]) <= 1  # not per read


def test_a_plugin_that_cannot_load_is_in_the_hub_health(hub):
    plugins = get(hub, "/wot/hub/properties/health").json()["plugins"]
    assert list(plugins["failed"]) == ["unloadable"]
    assert "ModuleNotFoundError: No module named 'wott_no_such_dependency'" in plugins["failed"]["unloadable"]


def test_frames_that_raise_restart_the_device_only_and_are_logged_once(hub, caplog):
    caplog.set_level(logging.WARNING)
    dev = hub.hub.devices["bad-frames"]
    start = dev.pipeline.restarts
    until(lambda: dev.pipeline.restarts >= start + 2, "two more restarts of bad-frames")
    assert dev.pipeline.frames >= 3 * (start + 2)  # it streams its 3 frames after every restart
    logged = [r for r in caplog.records if "frames exploded" in r.getMessage()]
    assert len(logged) <= 1  # once when it started failing (maybe before this test), not per restart
    until(lambda: get(hub, "/wot/hub/properties/health").json()["devices"]["bad-frames"]["reason"]
          == "frames() raised RuntimeError: frames exploded after 3", "bad-frames marked while it backs off")


def test_a_healthy_device_streams_without_a_gap_through_it_all(hub, sse_events):
    got = sse_events(f"{hub.hub.td_url('pad')}/events", 60, timeout=10)
    ids = [int(e.id) for e in got]
    assert ids == sorted(set(ids))
    assert hub.hub._history.writer.flush()
    recs, _ = hub.hub._history.reader.rows("pad", 0, 1 << 62, (KIND_EVENT, None), limit=10**7)
    assert ids == [r.seq for r in recs if ids[0] <= r.seq <= ids[-1]], "gap in the healthy device's stream"


def test_the_watcher_still_publishes_health_changes(hub):
    """``bad-health``'s health() raises on every read of the watcher; another device's change still
    arrives (the old watcher died on the first raise, and with it every healthChange)."""
    url = f"{hub.hub.td_url('hub')}/events/healthChange"
    seen: list[dict] = []
    connected = threading.Event()

    def read() -> None:
        from httpx_sse import connect_sse

        with httpx.Client(timeout=10) as c, connect_sse(c, "GET", url) as es:
            connected.set()
            for ev in es.iter_sse():
                seen.append(json.loads(ev.data))
                if seen[-1]["device"] == "ctl" and seen[-1]["state"] == "degraded":
                    return

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    assert connected.wait(10)
    time.sleep(0.2)
    from wott_hub.plugin_api import Health

    ctl = hub.hub.devices["ctl"].driver
    hub.call(ctl.set_health, Health.degraded, "test: flipped")
    reader.join(10)
    assert seen and seen[-1] == {**seen[-1], "device": "ctl", "state": "degraded", "reason": "test: flipped"}
    hub.call(ctl.set_health, Health.ok)


def test_hooks_that_raise_are_recorded_against_their_plugin(hub, caplog):
    caplog.set_level(logging.ERROR)
    registry = get_registry()
    td = {"@context": "https://www.w3.org/2022/wot/td/v1.1", "title": "foreign", "id": "urn:x"}
    assert hub.call(registry.claim, td) is None
    assert hub.call(registry.claim, td) is None
    assert hub.call(registry.demo_devices) == []  # its sys.exit() does not stop the hub either
    info = {p.name: p for p in registry.plugins()}
    assert "wott_hub_families: raised RuntimeError: families exploded" in info["hookbomb"].error
    assert "wott_hub_claim_td: raised RuntimeError: claim_td exploded" in info["hookbomb"].error
    assert "wott_hub_demo_devices: raised SystemExit: 3" in info["hookbomb"].error
    assert [r.getMessage().count("claim_td exploded") for r in caplog.records
            if "claim_td exploded" in r.getMessage()] == [1]  # twice raised, logged once
    assert get(hub, "/wot/hub/properties/health").json()["devices"]["pad"]["state"] == "ok"


def test_close_that_raises_removes_the_device_anyway(hub, caplog):
    caplog.set_level(logging.ERROR)
    hub.call(hub.hub.remove_device, "bad-close")
    assert "bad-close" not in {d["id"] for d in get(hub, "/wot/hub/properties/devices").json()}
    assert any("close() raised OSError: close exploded" in r.getMessage() for r in caplog.records)
    assert httpx.get(hub.hub.td_url("bad-close"), timeout=10).status_code == 404
    assert get(hub, "/wot/hub/properties/health").json()["devices"]["pad"]["state"] == "ok"


def test_the_same_isolation_in_a_worker_process(site, tmp_path, hub_thread, press_scene, wait_for):
    cfg = HubConfig(http_port=0, ws_port=0, history=False, workers=1,
                    devices=(press_scene("pad"), faulty("bad-health", "health"),
                             faulty("bad-prepare", "prepare")))
    ht = hub_thread(cfg).start()
    try:
        def devices():
            return get(ht, "/wot/hub/properties/health").json()["devices"]

        until(lambda: devices()["bad-health"]["state"] == "degraded", "the worker's report of bad-health")
        now = devices()
        assert now["bad-health"]["reason"] == "health() raised ValueError: health exploded"
        assert "prepare() raised ZeroDivisionError: prepare exploded" in now["bad-prepare"]["reason"]
        frames = now["bad-health"]["frames"]
        until(lambda: devices()["bad-health"]["frames"] > frames, "reports after the raising one")
        assert devices()["pad"]["state"] == "ok" and devices()["pad"]["frames"] > 0
    finally:
        ht.stop()


def test_run_prints_one_line_per_plugin_that_failed_to_load(site, tmp_path):
    import os
    import signal
    import subprocess

    cli = str(Path(sys.executable).parent / "wott-hub")
    proc = subprocess.Popen([cli, "run", "--port", "0", "--ws-port", "0", "--no-history", "--json"],
                            cwd=tmp_path, env=os.environ.copy(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        ready = json.loads(proc.stdout.readline())  # one JSON line: the warnings went to stderr
        assert ready["http"].startswith("http://127.0.0.1:")
    finally:
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=20)
    warnings = [line for line in err.splitlines() if line.startswith("warning: plugin")]
    assert warnings == [f"warning: plugin 'unloadable' not loaded: {warnings[0].split(': ', 2)[2]}"]
    assert "No module named 'wott_no_such_dependency'" in warnings[0]
