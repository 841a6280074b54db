"""Loading plugins from real entry points: failures stay with the plugin that caused them."""

from __future__ import annotations

import asyncio
import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from wott_hub.drivers.base import DriverError
from wott_hub.plugins import DeviceConfig, Registry, get_registry


def by_name(registry: Registry) -> dict:
    return {p.name: p for p in registry.plugins()}


def test_a_plugin_that_raises_on_import_is_listed_and_the_others_load(fake_site):
    plugins = by_name(Registry())
    broken = plugins["fakebroken"]
    assert broken.distribution == "wott-fake-broken" and broken.version == "1.2.3"
    assert broken.error == "RuntimeError: boom on import (wott_fake_broken.py:4)"
    assert broken.families == () and broken.hooks == ()
    assert plugins["fakemissing"].error.startswith(
        "ModuleNotFoundError: No module named 'wott_no_such_dependency'")
    assert plugins["fakeexit"].error.startswith("SystemExit: 3")
    good = plugins["fakegood"]
    assert good.error is None and good.version == "1.0.0" and good.distribution == "wott-fake-good"
    assert good.families == ("echo",)
    assert good.hooks == ("wott_hub_claim_td", "wott_hub_demo_devices", "wott_hub_families",
                          "wott_hub_open_device")
    assert plugins["builtin"].families == ("scene", "wot-remote") and plugins["builtin"].error is None


def test_bad_registrations_are_reported_not_raised(fake_site):
    registry = Registry()
    plugins = by_name(registry)
    sig = plugins["fakesig"]  # a hookimpl asking for an argument the spec does not have
    assert "PluginValidationError" in sig.error and "camera" in sig.error
    assert sig.hooks == () and not registry.pm.has_plugin("fakesig")
    assert plugins["faketypo"].error == "wott_hub_familes: not a wott-hub hook (misspelt?); never called"
    assert "typo" not in registry.families()
    result = plugins["fakeresult"]
    assert "family 'echo' is already provided by plugin 'fakegood'" in result.error
    assert "returned a dict, not a FamilyInfo" in result.error
    assert "family 'badschema': invalid settings schema" in result.error
    assert result.families == ("fine",)
    assert {f: i.plugin for f, i in registry.families().items()} == {
        "scene": "builtin", "wot-remote": "builtin", "echo": "fakegood", "flaky": "fakehook",
        "fine": "fakeresult"}


def test_a_hook_that_raises_is_recorded_and_the_other_plugins_still_answer(fake_site):
    registry = Registry()
    # demo_devices: fakehook raises, fakeresult returns garbage, fakegood answers.
    assert registry.demo_devices() == [DeviceConfig("echo-1", "echo", {"n": 2})]
    td = {"@context": ["https://www.w3.org/2022/wot/td/v1.1"], "title": "echo-td", "security": "nosec_sc"}
    assert registry.claim(td) == DeviceConfig("echo-td", "echo", {})
    assert registry.claim({**td, "title": "a thermostat"}) is None
    with pytest.raises(DriverError, match=r"plugin 'fakehook' raised KeyError: 'no such camera'"):
        registry.open_device(DeviceConfig("cam", "flaky", {}))
    errors = by_name(registry)["fakehook"].error
    for text in ("wott_hub_demo_devices: raised ValueError: demo exploded",
                 "wott_hub_claim_td: raised RuntimeError: claim_td exploded",
                 "wott_hub_open_device: raised KeyError: 'no such camera'"):
        assert text in errors
    garbage = by_name(registry)["fakeresult"].error
    assert "wott_hub_demo_devices: returned str, not a list of DeviceConfig" in garbage
    assert by_name(registry)["fakegood"].error is None
    # The same failure on every call is kept once.
    registry.demo_devices()
    assert by_name(registry)["fakehook"].error.count("demo exploded") == 1


def test_open_device_validates_settings_naming_the_field_and_fills_defaults(fake_site):
    registry = Registry()
    cases = {
        "'n': 'x' is not of type 'integer'": {"n": "x"},
        "'n': 0 is less than the minimum of 1": {"n": 0},
        "'m': unknown setting (allowed: n, shape)": {"m": 1},
        "'shape': 'barrel' is not one of ['flat', 'cylinder']": {"shape": "barrel"},
    }
    for message, settings in cases.items():
        with pytest.raises(DriverError) as e:
            registry.open_device(DeviceConfig("e1", "echo", settings))
        assert str(e.value) == f"device 'e1' (family 'echo'): setting {message}"
    installed = r"\(installed families: echo, fine, flaky, scene, wot-remote\)"
    with pytest.raises(DriverError, match=r"'nope' " + installed):
        registry.open_device(DeviceConfig("x", "nope", {}))
    with pytest.raises(DriverError, match="'fine' but does not implement wott_hub_open_device"):
        registry.open_device(DeviceConfig("x", "fine", {}))
    driver = registry.open_device(DeviceConfig("e1", "echo", {}))
    assert driver.n == 3 and driver.description.mesh.n_nodes == 256

    async def collect():
        return [f.t_ns async for f in driver.frames()]

    assert asyncio.run(collect()) == [1, 2, 3]


def test_the_environment_variable_limits_what_is_imported(fake_site, monkeypatch):
    monkeypatch.setenv("WOTT_HUB_PLUGINS", "wott_fake_good")  # a distribution name, any spelling
    assert [p.name for p in Registry().plugins()] == ["builtin", "fakegood"]
    assert "wott_fake_broken" not in sys.modules  # not even imported
    monkeypatch.setenv("WOTT_HUB_PLUGINS", " fakegood , fakebroken,nosuch ")
    plugins = by_name(Registry())
    assert list(plugins) == ["builtin", "fakebroken", "fakegood", "nosuch"]
    assert plugins["nosuch"].error == "named in WOTT_HUB_PLUGINS but no installed plugin is called 'nosuch'"
    monkeypatch.setenv("WOTT_HUB_PLUGINS", "")
    assert [p.name for p in Registry().plugins()] == ["builtin"]
    monkeypatch.delenv("WOTT_HUB_PLUGINS")
    names = set(by_name(Registry()))
    assert {"builtin", "fakegood", "fakebroken", "taxel"} <= names  # unset: every installed plugin


def test_get_registry_loads_once(fake_site):
    assert get_registry() is get_registry()


def test_device_config_from_a_hub_config_table():
    doc = tomllib.loads('[[device]]\nid = "left"\nfamily = "taxel-array"\nport = "/dev/ttyUSB0"\nrows = 8\n'
                        '[[device]]\nfamily = "scene"\n')
    cfg = DeviceConfig.from_table(doc["device"][0], "hub.toml: device[0]")
    assert cfg == DeviceConfig("left", "taxel-array", {"port": "/dev/ttyUSB0", "rows": 8})
    assert cfg.to_table() == doc["device"][0]
    with pytest.raises(DriverError, match=r"^hub.toml: device\[1\].id: required"):
        DeviceConfig.from_table(doc["device"][1], "hub.toml: device[1]")


def test_plugins_list_command_shows_failures_and_exits_cleanly(fake_site):
    env = {**os.environ, "PYTHONPATH": str(fake_site), "WOTT_HUB_PLUGINS": "fakegood,fakebroken,taxel"}
    command = Path(sys.executable).with_name("wott-hub")  # the installed console script
    out = subprocess.run([str(command), "plugins", "list", "--json"],
                         capture_output=True, text=True, env=env, timeout=60)
    assert out.returncode == 0, out.stderr
    listed = {p["name"]: p for p in json.loads(out.stdout)}
    assert listed["fakebroken"]["error"] == "RuntimeError: boom on import (wott_fake_broken.py:4)"
    assert listed["fakegood"] == {
        "name": "fakegood", "distribution": "wott-fake-good", "version": "1.0.0", "families": ["echo"],
        "hooks": ["wott_hub_claim_td", "wott_hub_demo_devices", "wott_hub_families",
                  "wott_hub_open_device"], "error": None}
    assert listed["taxel"]["families"] == ["taxel-array"] and listed["taxel"]["error"] is None

    from typer.testing import CliRunner

    from wott_hub.cli import app

    table = CliRunner().invoke(app, ["plugins", "list"], env={"COLUMNS": "200"})
    assert table.exit_code == 0
    assert "wott-fake-broken" in table.output and "boom on import" in table.output
    families = CliRunner().invoke(app, ["plugins", "families"], env={"COLUMNS": "200"})
    assert families.exit_code == 0 and "echo" in families.output
    echo = CliRunner().invoke(app, ["plugins", "families", "echo"], env={"COLUMNS": "200"})  # its settings
    assert echo.exit_code == 0 and "shape" in echo.output
