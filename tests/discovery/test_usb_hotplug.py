"""``[usb] adopt`` (issue 44 item 4, issue 45 item 4): a hub under ``umockdev-wrapper`` adopts a QT Py
(an AnySkin board) when it is plugged into the testbed, serves it over HTTP with the bytes the AnySkin
simulator writes into the pty behind its node, marks it disconnected when unplugged and serves it
again when plugged back in (on another node); a FlexiTac board (an Arduino Uno) is listed, never
adopted: only ``anyskin`` is."""

from __future__ import annotations

import contextlib
import re
import subprocess
import time

import httpx
import pytest
from wott_driver_anyskin.boards import BOARDS
from wott_driver_anyskin.simulator import AnySkinSimulator

from . import usb_records as R
from .usb_testbed import NodePort, UsbTestbed

QTPY_ID = f"anyskin-{R.QTPY_SERIAL}"
TRINKET_SERIAL = "5A3F0D2B"
TRINKET = (R.QTPY.replace("1-2", "1-7").replace("ttyACM0", "ttyACM3").replace("MINOR=0", "MINOR=3")
           .replace("166:0", "166:3").replace("80cb", "801e").replace(R.QTPY_SERIAL, TRINKET_SERIAL)
           .replace("QT_Py_M0", "Trinket_M0").replace("usb/001/005", "usb/001/008"))
"""ReSkin's board, a Trinket M0 (Arduino), plugged in before the hub starts."""


@contextlib.contextmanager
def _hub(bed: UsbTestbed, folder, config_text: str, banner: list[str] | None = None):
    """``wott-hub run`` inside the testbed with ``config_text``: its HTTP URL, once it is ready (``banner``
    gets the lines it printed)."""
    config = folder / "hub.toml"
    config.write_text(config_text)
    log = (folder / "hub.log").open("w")
    hub = bed.popen("run", "--config", str(config), stdout=subprocess.PIPE, stderr=log, cwd=folder)
    url = ""
    try:
        assert hub.stdout is not None
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline:
            line = hub.stdout.readline()
            if not line:
                break
            if banner is not None:
                banner.append(line.rstrip("\n"))
            if m := re.search(r"^\s+HTTP\s+(http://\S+)", line):
                url = m.group(1)
            if line.startswith("ready in "):
                break
        assert url, f"the hub did not start: {(folder / 'hub.log').read_text()[-3000:]}"
        yield url
    finally:
        hub.terminate()
        try:
            hub.wait(60)
        except subprocess.TimeoutExpired:
            hub.kill()
            hub.wait(10)
        if hub.stdout is not None:
            hub.stdout.close()
        log.close()


CONFIG = ('[hub]\nhttp_port = 0\nws_port = false\nhistory = false\n\n'
          '[directory]\nenabled = false\n\n[usb]\nadopt = ["anyskin"]\n')


SCENE_PAD = ('\n[[device]]\nid = "pad"\nfamily = "scene"\nshape = "flat"\nrate_hz = 30\n'
             'step = [{ kind = "press", at = [11.25, 11.25, 4.0], start_s = 0.5, duration_s = 1.0, '
             'depth_mm = 1.0, radius_mm = 4.0 }]\n')
"""A configured device beside the USB ones."""


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    bed = UsbTestbed()
    try:
        bed.load(R.UNO)
        bed.load(TRINKET)
        with _hub(bed, tmp_path_factory.mktemp("usb-hub"), CONFIG) as url:
            yield bed, url
    finally:
        bed.close()


def _health(url: str, thing: str) -> dict:
    return httpx.get(f"{url}/wot/hub/properties/health", timeout=30).json()["devices"].get(thing, {})


def test_a_board_plugged_in_is_served_unplugged_is_disconnected_and_back_when_plugged_again(rig, eventually):
    bed, url = rig
    assert httpx.get(f"{url}/wot/{QTPY_ID}", timeout=30).status_code == 404  # not plugged in yet
    sim = AnySkinSimulator(BOARDS["anyskin"], rate_hz=100)
    port = NodePort("/dev/ttyACM0")
    sim.line.port = port
    try:
        bed.plug(R.QTPY)
        port.plug(bed.pty("/dev/ttyACM0"))
        sim.start()
        td = eventually(lambda: (r := httpx.get(f"{url}/wot/{QTPY_ID}", timeout=30)).status_code == 200
                        and r.json(), timeout=90, what="the QT Py's Thing served")
        assert td["title"] == QTPY_ID and td["id"].endswith(f":device:{QTPY_ID}")
        first = eventually(lambda: (h := _health(url, QTPY_ID)).get("state") == "ok" and h["frames"] > 0
                           and h, timeout=90, what=lambda: f"frames from the QT Py: {_health(url, QTPY_ID)}")

        bed.unplug(R.QTPY)
        port.unplug()
        gone = eventually(lambda: (h := _health(url, QTPY_ID)).get("state") == "disconnected" and h,
                          timeout=60, what=lambda: f"the QT Py disconnected: {_health(url, QTPY_ID)}")
        assert gone["reason"].startswith("unplugged: USB 239a:80cb serial " + R.QTPY_SERIAL), gone
        assert gone["frames"] >= first["frames"]
        assert httpx.get(f"{url}/wot/{QTPY_ID}", timeout=30).status_code == 200  # the Thing stays

        bed.plug(R.QTPY_REPLUGGED)  # the same board, another port: /dev/ttyACM1
        port.plug(bed.pty("/dev/ttyACM1"), "/dev/ttyACM1")
        back = eventually(lambda: (h := _health(url, QTPY_ID)).get("state") == "ok"
                          and h["frames"] > gone["frames"] and h,
                          timeout=90, what=lambda: f"frames again after the replug: {_health(url, QTPY_ID)}")
        assert back["restarts"] == 1
    finally:
        sim.stop()


def test_a_board_present_at_start_is_adopted_with_its_board_preset(rig):
    _, url = rig
    td = httpx.get(f"{url}/wot/reskin-{TRINKET_SERIAL}", timeout=30)
    assert td.status_code == 200, td.text
    assert "reskin" in td.json()["description"]  # the Trinket's match sets board = "reskin"


def test_a_board_of_a_family_not_adopted_is_not_served(rig):
    _, url = rig
    assert httpx.get(f"{url}/wot/flexitac-{R.UNO_SERIAL}", timeout=30).status_code == 404
    devices = httpx.get(f"{url}/wot/hub/properties/health", timeout=30).json()["devices"]
    assert not any(d.startswith("flexitac") for d in devices)


def test_with_worker_processes_an_adopted_board_runs_in_the_hub_s_process(tmp_path, eventually):
    """``[hub] workers``: the configured devices run in a worker; a plugged-in board is opened here (the hub
    must close it on unplug and open it on another node), its frames flow all the same."""
    bed = UsbTestbed()
    sim = AnySkinSimulator(BOARDS["anyskin"], rate_hz=100)
    port = NodePort("/dev/ttyACM0")
    sim.line.port = port
    config = CONFIG.replace("history = false\n", "history = false\nworkers = 1\n") + SCENE_PAD
    try:
        with _hub(bed, tmp_path, config) as url:
            bed.plug(R.QTPY)
            port.plug(bed.pty("/dev/ttyACM0"))
            sim.start()
            eventually(lambda: (h := _health(url, QTPY_ID)).get("state") == "ok" and h["frames"] > 0,
                       timeout=90, what=lambda: f"frames from the QT Py: {_health(url, QTPY_ID)}")
            assert _health(url, "pad").get("state") in ("ok", "ended")  # the worker's device runs too
    finally:
        sim.stop()
        bed.close()


def test_without_udev_the_hub_serves_its_other_devices_and_says_why(tmp_path):
    """A machine without sysfs (umockdev's preload pointed at an empty folder): no USB device can be
    adopted; the hub starts anyway, its configured devices served, and its banner says why."""
    import os

    from .usb_testbed import WOTT_HUB, WRAPPER

    empty = tmp_path / "no-sysfs"
    empty.mkdir()

    class NoUdev:
        def popen(self, *args: str, **kw):
            env = {**os.environ, "UMOCKDEV_DIR": str(empty)}
            return subprocess.Popen([WRAPPER, WOTT_HUB, *args], env=env, text=True, **kw)

    config = CONFIG + SCENE_PAD
    banner: list[str] = []
    with _hub(NoUdev(), tmp_path, config, banner) as url:  # type: ignore[arg-type]
        assert httpx.get(f"{url}/wot/pad", timeout=30).status_code == 200
    (usb,) = [line for line in banner if line.startswith("  USB ")]
    assert "adopting anyskin when plugged in; NOT: udev is unavailable: /sys is not mounted here" in usb


CAMERA_PLUGIN = '''
"""A test family whose devices are USB cameras: it serves the node it is given as its title, and gives
frames only while that node is there (os.stat: under umockdev, the testbed's /dev)."""

import asyncio
import dataclasses
import os
import time

import numpy as np

from wott_hub.examples import example_device
from wott_hub.plugin_api import Driver, FamilyInfo, TactileFrame, UsbMatch, hookimpl


class NodeDriver(Driver):
    def __init__(self, description, device):
        super().__init__(description)
        self.device = device

    async def frames(self):
        while True:
            await asyncio.sleep(0.05)
            os.stat(self.device)  # FileNotFoundError once the node is gone: no frame from it
            yield TactileFrame(time.time_ns(), np.zeros((self.description.mesh.n_nodes, 3)))


@hookimpl
def wott_hub_families():
    schema = {"type": "object", "additionalProperties": False, "required": ["device"],
              "properties": {"device": {"type": "string", "pattern": "^/dev/video[0-9]+$"}}}
    return [FamilyInfo("test-cam", "A USB camera of the tests.", schema)]


@hookimpl
def wott_hub_open_device(config):
    desc = example_device("flat", config.id)
    device = config.settings["device"]
    return NodeDriver(dataclasses.replace(desc, title=device, family="test-cam"), device)


@hookimpl
def wott_hub_usb_devices():
    return [UsbMatch("test-cam", "video4linux", "a test camera", vendor_id="f055", product_ids=("c0de",),
                     setting="device", id_prefix="cam")]
'''


def _camera(port: str, index: int) -> str:
    ids = ("f055", "c0de", "CAM42", "Tests", "Camera")
    return R.join(R._usb(port, *ids[:3], 9, *ids[3:]),
                  R._video(port, index, *ids, "Camera: Camera", True),  # capture
                  R._video(port, index + 1, *ids, "Camera: Camera", False))  # metadata


def test_a_camera_plugged_in_gets_its_capture_node_as_its_device_setting(tmp_path, eventually):
    """The video4linux path end to end, with a family of the test's own (an installed plugin: a
    dist-info on PYTHONPATH): plugged in, the camera is served with ``device`` = its capture node;
    unplugged, disconnected; plugged into another port, frames again from its new node (the old one is
    gone: a driver reading it would give none). The Thing, its TD included, stays the one first served."""
    site = tmp_path / "site"
    site.mkdir()
    (site / "wott_test_usbcam.py").write_text(CAMERA_PLUGIN)
    info = site / "wott_test_usbcam-0.1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: wott-test-usbcam\nVersion: 0.1.0\n")
    (info / "entry_points.txt").write_text("[wott-hub]\nusbcam = wott_test_usbcam\n")
    bed = UsbTestbed()
    bed.extra_env = {"PYTHONPATH": str(site), "WOTT_HUB_PLUGINS": "usbcam"}
    config = CONFIG.replace('adopt = ["anyskin"]', 'adopt = ["test-cam"]')
    try:
        with _hub(bed, tmp_path, config) as url:
            bed.plug(_camera("1-8", 4))
            td = eventually(lambda: (r := httpx.get(f"{url}/wot/cam-CAM42", timeout=30)).status_code == 200
                            and r.json(), timeout=90, what="the camera's Thing served")
            assert td["title"] == "/dev/video4"  # the capture node, not the metadata node /dev/video5
            eventually(lambda: _health(url, "cam-CAM42").get("frames", 0) > 0, timeout=60, what="frames")
            bed.unplug(_camera("1-8", 4))
            eventually(lambda: _health(url, "cam-CAM42").get("state") == "disconnected", timeout=60,
                       what=lambda: f"disconnected: {_health(url, 'cam-CAM42')}")
            frames = _health(url, "cam-CAM42")["frames"]
            bed.plug(_camera("1-9", 6))
            back = eventually(lambda: (h := _health(url, "cam-CAM42")).get("state") == "ok"
                              and h["frames"] > frames and h, timeout=90,
                              what=lambda: f"frames from the new node: {_health(url, 'cam-CAM42')}")
            assert back["restarts"] == 1 and back["reason"] == ""
    finally:
        bed.close()


def test_a_digit_and_a_mini_plugged_in_are_adopted_by_the_gel_families(tmp_path, eventually):
    """Issue 44 item 4 with the gel plugin's own families: each camera served as ``<family>-<serial>``
    when plugged in (its driver opens the capture node when it runs: the testbed's node is no camera,
    so no frame comes, which the health says), disconnected when unplugged."""
    bed = UsbTestbed()
    config = CONFIG.replace('adopt = ["anyskin"]', 'adopt = ["digit", "gelsight-mini"]')
    digit, mini = f"digit-{R.DIGIT_SERIAL}", f"gelsight-mini-{R.MINI_SERIAL}"
    try:
        with _hub(bed, tmp_path, config) as url:
            bed.plug(R.DIGIT)
            bed.plug(R.MINI)
            for thing in (digit, mini):
                td = eventually(lambda t=thing: (r := httpx.get(f"{url}/wot/{t}", timeout=30)).status_code
                                == 200 and r.json(), timeout=90, what=f"{thing} served")
                assert td["id"].endswith(f":device:{thing}"), td["id"]
            served = httpx.get(f"{url}/wot/hub/properties/devices", timeout=30).json()
            assert {d["id"]: d["family"] for d in served} == {digit: "digit", mini: "gelsight-mini"}
            bed.unplug(R.DIGIT)
            gone = eventually(lambda: (h := _health(url, digit)).get("state") == "disconnected"
                              and "unplugged" in h["reason"] and h, timeout=60,
                              what=lambda: f"the DIGIT disconnected: {_health(url, digit)}")
            assert f"serial {R.DIGIT_SERIAL} left /dev/video0" in gone["reason"]
            assert "unplugged" not in _health(url, mini).get("reason", "")  # the Mini is still plugged in
    finally:
        bed.close()
