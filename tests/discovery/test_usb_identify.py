"""The rule that turns a udev device's properties into a device of a family (``discovery.usb.identify``):
no udev here, the properties are given as udev gives them."""

from __future__ import annotations

from wott_hub.discovery.usb import identify
from wott_hub.plugins import DeviceConfig, Registry, UsbMatch

MATCHES = Registry(only=["anyskin", "taxel", "xela"]).usb_matches()
FTDI = {"DEVNAME": "/dev/ttyUSB0", "ID_VENDOR_ID": "0403", "ID_MODEL_ID": "6001",
        "ID_SERIAL_SHORT": "FT6S4DSP"}


def test_a_camera_s_metadata_node_is_not_a_device():
    cam = UsbMatch("cam", "video4linux", "a camera", vendor_id="1234", setting="device")
    props = {"DEVNAME": "/dev/video1", "ID_VENDOR_ID": "1234", "ID_SERIAL_SHORT": "7"}
    assert identify("video4linux", "/sys/v1", {**props, "ID_V4L_CAPABILITIES": ":"}, [cam]) is None
    found = identify("video4linux", "/sys/v1", {**props, "ID_V4L_CAPABILITIES": ":capture:"}, [cam])
    assert found is not None and found.config() == DeviceConfig("cam-7", "cam", {"device": "/dev/video1"})


def test_a_device_two_plugins_claim_is_the_adopted_family_s_and_lists_the_other():
    listed = identify("tty", "/sys/t", FTDI, MATCHES)
    assert listed is not None and listed.family == "taxel-array"
    assert [m.family for m in listed.others] == ["xela"]
    assert listed.config().settings == {"protocol": "3dvitac", "port": "/dev/ttyUSB0"}
    # adopting only xela: xela's match cannot adopt, so the board stays the taxel plugin's
    assert identify("tty", "/sys/t", FTDI, MATCHES, adopt=["xela"]).family == "taxel-array"


def test_an_id_without_a_serial_is_the_node_s_and_odd_serials_become_a_valid_id():
    bare = identify("tty", "/sys/t", {**FTDI, "ID_SERIAL_SHORT": ""}, MATCHES)
    assert bare is not None and bare.thing_id == "3dvitac-ttyUSB0"
    odd = identify("tty", "/sys/t", {**FTDI, "ID_SERIAL_SHORT": "A B/C"}, MATCHES)
    assert odd is not None and odd.thing_id == "3dvitac-A-B-C"


def test_a_udev_spelling_in_upper_case_hex_still_matches_and_another_subsystem_does_not():
    qtpy = {"DEVNAME": "/dev/ttyACM0", "ID_VENDOR_ID": "239A", "ID_MODEL_ID": "80CB", "ID_SERIAL_SHORT": "1"}
    found = identify("tty", "/sys/t", qtpy, MATCHES)
    assert found is not None and found.family == "anyskin" and found.config().settings["board"] == "anyskin"
    assert identify("video4linux", "/sys/t", qtpy, MATCHES) is None
    assert identify("tty", "/sys/t", {**qtpy, "DEVNAME": ""}, MATCHES) is None  # no node: nothing to open
