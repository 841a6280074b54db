"""``wott-hub discover --usb`` (issue 44 item 4, issue 45 item 4) on a umockdev testbed: the CLI runs
under ``umockdev-wrapper``, so its libudev reads the testbed's devices, described by their udev
properties (usb_records.py)."""

from __future__ import annotations

import json

import pytest

from wott_hub.plugins import get_registry

from . import usb_records as R
from .usb_testbed import UsbTestbed


@pytest.fixture
def testbed():
    bed = UsbTestbed()
    yield bed
    bed.close()


@pytest.fixture
def adopt_anyskin(tmp_path):
    config = tmp_path / "hub.toml"
    config.write_text('[usb]\nadopt = ["anyskin"]\n')
    return config


def _lines(res) -> dict[str, str]:
    assert res.returncode == 0, res.stderr
    assert "Traceback" not in res.stderr
    lines = res.stdout.splitlines()
    return {line.split()[0]: line for line in lines}


def test_a_digit_a_mini_and_an_anyskin_qt_py_are_listed_with_their_serials(testbed, adopt_anyskin):
    for record in (R.DIGIT, R.MINI, R.QTPY, R.UNO, R.FTDI):
        testbed.load(record)
    lines = _lines(testbed.run("discover", "--usb", "--config", str(adopt_anyskin)))
    # one line per device: the DIGIT's metadata node (/dev/video1) is not a device of its own
    assert sorted(lines) == ["/dev/ttyACM0", "/dev/ttyACM2", "/dev/ttyUSB0", "/dev/video0", "/dev/video2"]
    digit = lines["/dev/video0"].split()
    assert digit[1:6] == ["digit", "2833:0209", "serial", R.DIGIT_SERIAL, "id"]
    assert digit[6] == f"digit-{R.DIGIT_SERIAL}"
    # the gel plugin's family (issue 44): not adopted here either way, and said why
    why = "not in [usb] adopt" if "digit" in get_registry().families() else "family 'digit' is not installed"
    assert f"adopt: no ({why})" in lines["/dev/video0"]
    mini = lines["/dev/video2"]
    assert f"gelsight-mini  0c45:636d  serial {R.MINI_SERIAL}  id gelsight-mini-{R.MINI_SERIAL}" in mini
    qtpy = lines["/dev/ttyACM0"]
    assert f"anyskin  239a:80cb  serial {R.QTPY_SERIAL}  id anyskin-{R.QTPY_SERIAL}  adopt: yes" in qtpy
    assert "QT Py M0" in qtpy
    uno = lines["/dev/ttyACM2"]  # FlexiTac's board: listed, not adopted (only anyskin is)
    assert f"taxel-array  2341:0043  serial {R.UNO_SERIAL}  id flexitac-{R.UNO_SERIAL}" in uno
    assert "adopt: no (not in [usb] adopt)" in uno
    ftdi = lines["/dev/ttyUSB0"]  # 3D-ViTac's board, or XELA's CAN adapter: both said
    assert f"taxel-array  0403:6001  serial {R.FTDI_SERIAL}  id 3dvitac-{R.FTDI_SERIAL}" in ftdi
    assert "also xela?" in ftdi


def test_at_80_columns_a_line_drops_what_the_device_is_never_a_value(testbed, adopt_anyskin):
    testbed.load(R.QTPY)
    testbed.load(R.FTDI)
    lines = _lines(testbed.run("discover", "--usb", "--config", str(adopt_anyskin), columns=80))
    assert lines["/dev/ttyACM0"].endswith(f"id anyskin-{R.QTPY_SERIAL}  adopt: yes")  # no room for the label
    assert "QT Py" not in lines["/dev/ttyACM0"]
    assert lines["/dev/ttyUSB0"].endswith("adopt: no (not in [usb] adopt)  [also xela?]")


def test_the_json_says_what_each_device_would_be_adopted_as(testbed, adopt_anyskin):
    testbed.load(R.QTPY)
    testbed.load(R.FTDI)
    res = testbed.run("discover", "--usb", "--json", "--config", str(adopt_anyskin))
    assert res.returncode == 0, res.stderr
    rows = {r["node"]: r for r in json.loads(res.stdout)}
    qtpy = rows["/dev/ttyACM0"]
    assert qtpy["adopted"] is True and qtpy["id"] == f"anyskin-{R.QTPY_SERIAL}" and qtpy["usb"] == "239a:80cb"
    assert rows["/dev/ttyUSB0"]["also"] == ["xela"] and rows["/dev/ttyUSB0"]["adopted"] is False


def test_without_a_config_nothing_would_be_adopted(testbed):
    testbed.load(R.QTPY)
    lines = _lines(testbed.run("discover", "--usb"))
    assert "adopt: no (not in [usb] adopt (no --config))" in lines["/dev/ttyACM0"]


def test_nothing_plugged_in_says_so(testbed):
    testbed.load(R.DIGIT.split("\n\n")[0])  # a USB device, but no node a plugin knows
    res = testbed.run("discover", "--usb")
    assert res.returncode == 0 and res.stdout.strip() == "no known USB device is plugged in"


def test_without_udev_it_is_one_line(tmp_path, one_error_line):
    """A machine (a container) without sysfs: umockdev's preload pointed at an empty folder."""
    import os
    import subprocess

    from .usb_testbed import WOTT_HUB, WRAPPER

    env = {**os.environ, "UMOCKDEV_DIR": str(tmp_path)}
    res = subprocess.run([WRAPPER, WOTT_HUB, "discover", "--usb"], env=env, capture_output=True, text=True,
                         timeout=120)
    line = one_error_line(res, 5)
    assert "udev is unavailable" in line and "/sys" in line
