"""``[usb] adopt`` (issue 44 item 4, issue 45 item 4): a hub under ``umockdev-wrapper`` adopts a QT Py
(an AnySkin board) when it is plugged into the testbed, serves it over HTTP with the bytes the AnySkin
simulator writes into the pty behind its node, marks it disconnected when unplugged and serves it
again when plugged back in (on another node); a FlexiTac board (an Arduino Uno) is listed, never
adopted: only ``anyskin`` is."""

from __future__ import annotations

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


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    folder = tmp_path_factory.mktemp("usb-hub")
    bed = UsbTestbed()
    bed.load(R.UNO)
    bed.load(TRINKET)
    config = folder / "hub.toml"
    config.write_text('[hub]\nhttp_port = 0\nws_port = false\nhistory = false\n\n'
                      '[directory]\nenabled = false\n\n[usb]\nadopt = ["anyskin"]\n')
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
            if m := re.search(r"^\s+HTTP\s+(http://\S+)", line):
                url = m.group(1)
            if line.startswith("ready in "):
                break
        assert url, f"the hub did not start: {(folder / 'hub.log').read_text()[-3000:]}"
        yield bed, url
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
