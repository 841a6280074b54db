"""Fleet management while the hub runs: addDevice, removeDevice, restartDevice, ``wott-hub devices``.

A real hub on loopback (history, TD directory, mDNS on loopback). An SSE client
on one device stays connected while others are added, restarted and removed,
and sees no gap in its sequence numbers (checked against history). A device
whose open fails at start is retried with backoff and served once it opens
(a test family whose open fails twice); the CLI talks to the running hub over HTTP.
"""

from __future__ import annotations

import re
import threading
import time

import httpx
import pytest
from typer.testing import CliRunner

from wott_hub.config import HubConfig
from wott_hub.events.record import KIND_EVENT
from wott_hub.network.config import DiscoveryConfig
from wott_hub.plugin_api import MATERIALS, DeviceDescription, DriverError, FamilyInfo, hookimpl
from wott_hub.plugins import DeviceConfig

FAILS = 2  # the flaky device's open fails this many times, then succeeds


class FlakyPlugin:
    """A family whose devices fail to open ``fail`` times (a camera not plugged in yet), then open."""

    def __init__(self) -> None:
        self.attempts: dict[str, int] = {}

    @hookimpl
    def wott_hub_families(self):
        return [FamilyInfo("test-flaky", "opens after failing a few times", {
            "type": "object", "properties": {"fail": {"type": "integer", "minimum": 0}},
            "additionalProperties": False})]

    @hookimpl
    def wott_hub_open_device(self, config):
        from wott_hub.drivers.scene import SceneDriver
        from wott_hub.examples import example_device
        from wott_hub.sim.scene import Scene

        n = self.attempts[config.id] = self.attempts.get(config.id, 0) + 1
        if n <= config.settings.get("fail", 0):
            raise DriverError(f"device {config.id!r}: camera not found (attempt {n})")
        desc = example_device("flat", device_id=config.id)
        assert isinstance(desc, DeviceDescription) and MATERIALS
        return SceneDriver(desc, Scene("rest", (), loop=True), rate_hz=10.0)


@pytest.fixture(scope="module")
def flaky():
    from wott_hub.plugins import get_registry

    plugin = FlakyPlugin()
    get_registry().register(plugin, f"test-flaky-{id(plugin)}")
    return plugin


@pytest.fixture(scope="module")
def live(tmp_path_factory, hub_thread, scene, flaky):
    cfg = HubConfig(http_port=0, ws_port=0, database=str(tmp_path_factory.mktemp("fleet") / "hub.db"),
                    discovery=DiscoveryConfig(mdns=True, browse=False, interfaces=("127.0.0.1",)),
                    devices=(scene("a", "flat", rate_hz=20.0), scene("b", "flat", rate_hz=20.0),
                             DeviceConfig("late", "test-flaky", {"fail": FAILS}),
                             DeviceConfig("typo", "test-flaky", {"fial": 1})))
    ht = hub_thread(cfg).start()
    yield ht
    ht.stop()


def _act(live, name, body):
    return httpx.post(f"{live.url}/wot/hub/actions/{name}", json=body, timeout=30)


def _health(live):
    return httpx.get(f"{live.url}/wot/hub/properties/health", timeout=10).json()["devices"]


def _directory_ids(live):
    return {td["id"] for td in httpx.get(f"{live.url}/things", timeout=10).json()}


def _wait(predicate, what, timeout=15.0):
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, f"{what}: not within {timeout} s"
        time.sleep(0.1)


class SSE:
    """An SSE client reading ``url`` in a thread until ``stop()``: the ids it got."""

    def __init__(self, url: str) -> None:
        self.ids: list[int] = []
        self.error: BaseException | None = None
        self._stop = threading.Event()
        self._connected = threading.Event()
        self.thread = threading.Thread(target=self._run, args=(url,), daemon=True)
        self.thread.start()
        assert self._connected.wait(10)

    def _run(self, url: str) -> None:
        from httpx_sse import connect_sse

        try:
            with httpx.Client(timeout=20) as c, connect_sse(c, "GET", url) as es:
                self._connected.set()
                for ev in es.iter_sse():
                    self.ids.append(int(ev.id))
                    if self._stop.is_set():
                        return
        except BaseException as e:
            self.error = e
            self._connected.set()

    def stop(self) -> list[int]:
        self._stop.set()
        self.thread.join(20)
        assert self.error is None and not self.thread.is_alive(), f"the stream broke: {self.error!r}"
        return self.ids


def test_the_hub_td_declares_the_fleet_actions(live):
    td = httpx.get(f"{live.url}/wot/hub", timeout=10).json()
    for name in ("addDevice", "removeDevice", "restartDevice"):
        aff = td["actions"][name]
        assert aff["input"]["type"] == "object" and aff["output"]["type"] == "object"
        (form,) = aff["forms"]
        assert form["op"] == ["invokeaction"] and form["htv:methodName"] == "POST"
        assert form["href"] == f"{live.url}/wot/hub/actions/{name}"


def test_add_restart_remove_never_interrupt_another_devices_stream(live, scene):
    stream = SSE(f"{live.hub.td_url('a')}/events")
    time.sleep(0.3)
    table = scene("c", "flat", rate_hz=20.0).to_table()
    r = _act(live, "addDevice", {"id": "c", "family": "scene",
                                 "settings": {k: v for k, v in table.items() if k not in ("id", "family")}})
    assert r.status_code == 200, r.text
    out = r.json()
    assert out["id"] == "c" and out["td"] == live.hub.td_url("c") and "restart" in out["actions"]
    assert httpx.get(out["td"], timeout=10).json()["title"] == "c"
    td_id = live.hub.devices["c"].thing.td["id"]
    _wait(lambda: td_id in _directory_ids(live), "the added device in the directory")
    _wait(lambda: "c" in live.hub._network.discovery._names, "the added device announced on mDNS")
    r = _act(live, "restartDevice", {"id": "b"})
    assert r.status_code == 200 and r.json()["outcome"] == "ok", r.text
    time.sleep(0.3)
    r = _act(live, "removeDevice", {"id": "c"})
    assert r.status_code == 200 and r.json() == {"id": "c", "removed": True}
    assert httpx.get(live.hub.td_url("c"), timeout=10).status_code == 404
    _wait(lambda: td_id not in _directory_ids(live), "the removed device gone from the directory")
    assert "c" not in live.hub._network.discovery._names
    n = len(stream.ids)
    deadline = time.monotonic() + 60  # a hang's bound: the stream goes on, counted, not timed
    while len(stream.ids) <= n and time.monotonic() < deadline:
        time.sleep(0.05)
    ids = stream.stop()
    assert len(ids) > n, "the stream stopped"
    assert live.hub._history.writer.flush()
    recs, _ = live.hub._history.reader.rows("a", 0, 1 << 62, (KIND_EVENT, None), limit=10**7)
    recorded = sorted(r.seq for r in recs)
    assert ids == [s for s in recorded if ids[0] <= s <= ids[-1]], "gap in a's stream"
    assert _health(live)["b"]["restarts"] == 1


def test_mistakes_get_the_status_of_their_meaning_naming_the_field(live, scene):
    settings = {k: v for k, v in scene("x", "flat").to_table().items() if k not in ("id", "family")}
    cases = [
        ({"id": "x", "family": "nope", "settings": {}}, 400, "family"),
        ({"id": "x", "family": "scene", "settings": {**settings, "rate_hz": -1}}, 400, "rate_hz"),
        ({"id": "x", "family": "scene", "settings": {**settings, "colour": "red"}}, 400, "colour"),
        ({"family": "scene", "settings": settings}, 400, "id"),
        ({"id": "x", "family": "scene", "settings": 3}, 400, "settings"),
        ({"id": "a", "family": "scene", "settings": settings}, 409, "'a'"),
        ({"id": "hub", "family": "scene", "settings": settings}, 409, "hub"),
    ]
    for body, status, named in cases:
        r = _act(live, "addDevice", body)
        assert r.status_code == status and named in r.json()["detail"], (body, r.text)
        assert r.headers["content-type"].startswith("application/problem+json")
    for name in ("removeDevice", "restartDevice"):
        r = _act(live, name, {"id": "ghost"})
        assert r.status_code == 404 and "ghost" in r.json()["detail"]
        r = _act(live, name, {})
        assert r.status_code == 400 and "'id'" in r.json()["detail"]
    assert "x" not in live.hub.devices


def test_a_device_that_fails_to_open_is_retried_with_backoff_then_served(live, flaky):
    _wait(lambda: "late" in live.hub.devices, "the flaky device served", timeout=20)
    assert flaky.attempts["late"] == FAILS + 1  # once at start, then each retry until it opened
    assert _health(live)["late"]["state"] in ("ok", "running", "starting")
    td_id = live.hub.devices["late"].thing.td["id"]
    _wait(lambda: td_id in _directory_ids(live), "the late device in the directory")
    _wait(lambda: "late" in live.hub._network.discovery._names, "the late device announced on mDNS")
    typo = _health(live)["typo"]  # settings its family refuses: never opens, not retried
    assert typo["state"] == "failed" and "fial" in typo["reason"] and "not retried" in typo["reason"]
    assert flaky.attempts.get("typo") is None


def test_the_reason_of_a_device_being_retried_is_in_health(live, flaky, scene):
    r = _act(live, "addDevice", {"id": "soon", "family": "test-flaky", "settings": {"fail": 1}})
    assert r.status_code == 422 and "camera not found" in r.json()["detail"]  # added at run time: said now
    assert "soon" not in _health(live)


def test_the_cli_manages_a_running_hub(live, tmp_path, scene):
    from wott_hub.cli import app

    cli = CliRunner()
    url = ["--url", live.url]
    toml = tmp_path / "more.toml"
    table = scene("d", "flat", rate_hz=20.0).to_table()
    lines = ["[[device]]", 'id = "d"', 'family = "scene"', f"shape = {table['shape']!r}".replace("'", '"'),
             "loop = true", "rate_hz = 20.0"]
    steps = "\n".join("[[device.step]]\n" + "\n".join(f"{k} = {_toml(v)}" for k, v in s.items())
                      for s in table["step"])
    toml.write_text("\n".join(lines) + "\n" + steps + "\n")
    res = cli.invoke(app, ["devices", "add", str(toml), *url])
    assert res.exit_code == 0, res.output
    assert res.output.startswith("added d: ") and "restart" in res.output
    res = cli.invoke(app, ["devices", "list", *url])
    assert res.exit_code == 0, res.output
    assert re.search(r"^d +scene ", res.output, re.M) and re.search(r"^typo ", res.output, re.M)
    res = cli.invoke(app, ["devices", "restart", "d", *url])
    assert res.exit_code == 0 and res.output.startswith("restarted d")
    res = cli.invoke(app, ["devices", "health", "d", *url])
    assert res.exit_code == 0 and '"restarts": 1' in res.output and '"lastRestart"' in res.output
    res = cli.invoke(app, ["devices", "add", str(toml), *url])
    assert res.exit_code == 4 and "already served" in res.output  # id taken: 409, exit 4
    res = cli.invoke(app, ["devices", "remove", "d", *url])
    assert res.exit_code == 0 and res.output.strip() == "removed d"
    res = cli.invoke(app, ["devices", "remove", "d", *url])
    assert res.exit_code == 3 and "no device 'd'" in res.output
    bad = tmp_path / "bad.toml"
    bad.write_text('id = "e"\nfamily = "nope"\n')
    res = cli.invoke(app, ["devices", "add", str(bad), *url])
    assert res.exit_code == 2 and "unknown family" in res.output
    res = cli.invoke(app, ["devices", "list", "--url", "http://127.0.0.1:9"])
    assert res.exit_code == 1 and "cannot reach the hub" in res.output


def _toml(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, list):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    if isinstance(v, str):
        return f'"{v}"'
    return repr(v)
