"""One test per hook, named ``test_hook_<hook>`` (datasette's convention, checked by test_docs.py): each
calls the hook through the registry on the plugins that really implement it, first-party ones included."""

from __future__ import annotations

import pytest

from wott_hub.discovery.usb import identify
from wott_hub.examples import example_device
from wott_hub.plugin_api import hookimpl
from wott_hub.plugins import DeviceConfig, Registry, UsbMatch
from wott_hub.tactile import DeviceDescription
from wott_hub.td.builder import build_tactile_td


@pytest.fixture(scope="module")
def registry() -> Registry:
    return Registry(only=["builtin", "taxel", "barrel", "flatpad"])


def test_hook_wott_hub_families(registry):
    families = registry.families()
    assert {f: i.plugin for f, i in families.items()} == {
        "scene": "builtin", "wot-remote": "builtin", "taxel-array": "taxel", "barrel-vision": "barrel",
        "flat-vision": "flatpad"}
    taxel = families["taxel-array"].schema  # the model's JSON Schema, derived by the registry
    assert taxel["type"] == "object" and {"port", "rows", "cols"} <= set(taxel["properties"])


def test_hook_wott_hub_open_device(registry):
    config = DeviceConfig("t", "taxel-array", {"port": "/dev/null", "rows": 4, "cols": 6})
    driver = registry.open_device(config)  # not started: nothing is opened until frames()
    assert isinstance(driver.description, DeviceDescription)
    assert driver.description.mesh.n_nodes == 4 * 6


def test_hook_wott_hub_demo_devices(registry):
    demo = registry.demo_devices()
    families = registry.families()
    assert {d.family for d in demo} == {"taxel-array", "barrel-vision", "flat-vision"}
    assert all(families[d.family].plugin != "builtin" for d in demo)
    assert len({d.id for d in demo}) == len(demo)


def test_hook_wott_hub_claim_td(registry):
    td = build_tactile_td(example_device("flat"), base="http://127.0.0.1:9/")
    claimed = registry.claim(td)
    assert claimed is not None and claimed.family == "wot-remote" and claimed.settings["td"]["id"] == td["id"]
    assert registry.claim({"@context": "https://www.w3.org/2022/wot/td/v1.1", "title": "a lamp"}) is None


def test_hook_wott_hub_usb_devices(registry):
    """The built-in plugin's gel cameras and the taxel plugin's boards, each claiming the udev properties
    of its device; a QT Py is not among them here (the anyskin plugin is not loaded)."""
    matches = registry.usb_matches()
    assert {m.family for m in matches} == {"digit", "gelsight-mini", "taxel-array"}
    assert all(m.problem() is None for m in matches)
    digit = identify("video4linux", "/sys/v0", {"DEVNAME": "/dev/video0", "ID_MODEL": "DIGIT",
                                                "ID_VENDOR_ID": "2833", "ID_MODEL_ID": "0209",
                                                "ID_SERIAL_SHORT": "D20001",
                                                "ID_V4L_CAPABILITIES": ":capture:"},
                     matches)
    assert digit is not None and digit.thing_id == "digit-D20001"
    assert digit.config() == DeviceConfig("digit-D20001", "digit", {"device": "/dev/video0"})
    uno = identify("tty", "/sys/t0", {"DEVNAME": "/dev/ttyACM1", "ID_VENDOR_ID": "2341",
                                      "ID_MODEL_ID": "0043", "ID_SERIAL_SHORT": "85734323430351D0E1C1"},
                   matches)
    assert uno is not None and uno.config() == DeviceConfig(
        "flexitac-85734323430351D0E1C1", "taxel-array", {"protocol": "flexitac", "port": "/dev/ttyACM1"})
    qtpy = {"DEVNAME": "/dev/ttyACM0", "ID_VENDOR_ID": "239a", "ID_MODEL_ID": "80cb"}
    assert identify("tty", "/sys/t1", qtpy, matches) is None
    assert identify("tty", "/sys/t1", qtpy, Registry(only=["anyskin"]).usb_matches()) is not None


def test_a_usb_match_that_can_never_match_or_raises_is_an_error_of_its_plugin():
    class Bad:
        @staticmethod
        @hookimpl
        def wott_hub_usb_devices():
            return [UsbMatch("pad", "usb", "a pad", vendor_id="1234"),
                    UsbMatch("pad", "tty", "a pad", vendor_id="12G4"),
                    UsbMatch("pad", "tty", "a pad"),
                    "a pad",
                    UsbMatch("pad", "tty", "a pad", vendor_id="1234", product_ids=("0001",), setting="port")]

    class Bomb:
        @staticmethod
        @hookimpl
        def wott_hub_usb_devices():
            raise RuntimeError("usb exploded")

    reg = Registry(entry_points=False, builtins=False)
    reg.register(Bad, "bad")
    reg.register(Bomb, "bomb")
    kept = [m for m in reg.usb_matches() if m.family == "pad"]
    assert len(kept) == 1 and kept[0].setting == "port"
    (info,) = [p for p in reg.plugins() if p.name == "bad"]
    assert info.error is not None
    for said in ("subsystem 'usb'", "'12G4' is not 4 lower-case hex digits", "no rule", "returned a str"):
        assert said in info.error, info.error
    (bomb,) = [p for p in reg.plugins() if p.name == "bomb"]  # a plugin that raises: its own error only
    assert bomb.error is not None and "wott_hub_usb_devices: raised RuntimeError: usb exploded" in bomb.error


def test_hook_wott_hub_calibrate(tmp_path):
    """The gel plugin's depth calibration from Taxim's real Mini ball presses; a family without one, an
    unknown option and missing data are each one refusal saying which."""
    from importlib import resources

    from wott_hub.errors import SettingsError

    registry = Registry(only=["gel", "flatpad"])
    with resources.as_file(resources.files("taxim") / "calib" / "gelsight_mini" / "dataPack.npz") as data:
        summary = registry.calibrate("gelsight-mini", str(data), str(tmp_path / "d.npz"),
                                     {"ball_diameter_mm": "4"})
        assert summary.startswith(f"wrote {tmp_path / 'd.npz'}") and "24 presses of a 4 mm ball" in summary
        with pytest.raises(SettingsError, match="--option colour: unknown"):
            registry.calibrate("gelsight-mini", str(data), str(tmp_path / "e.npz"), {"colour": "red"})
    with pytest.raises(SettingsError, match="has no calibration"):
        registry.calibrate("flat-vision", "x", str(tmp_path / "f.npz"), {})
    with pytest.raises(SettingsError, match="not a ball-press pack"):
        registry.calibrate("digit", str(tmp_path / "missing.npz"), str(tmp_path / "g.npz"),
                           {"ball_diameter_mm": "4"})
