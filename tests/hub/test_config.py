"""The hub config file: the documented example loads; mistakes name the file, table and key."""

from __future__ import annotations

from pathlib import Path

import pytest

from wott_hub.config import ConfigError, HubConfig

EXAMPLE = Path(__file__).resolve().parents[2] / "docs" / "hub.example.toml"


def test_the_documented_example_loads_and_its_device_opens(tmp_path):
    cfg = HubConfig.load(EXAMPLE)
    assert (cfg.name, cfg.http_port, cfg.ws_port, cfg.retention_days) == ("lab-hub", 8080, 8081, 30.0)
    assert cfg.database == str(EXAMPLE.parent / "wott-hub.db")  # relative to the config file
    assert not cfg.demo and [d.id for d in cfg.devices] == ["finger-1"]
    dev = cfg.devices[0]
    assert dev.family == "scene" and dev.settings["shape"] == "flat" and len(dev.settings["step"]) == 2
    from wott_hub.plugins import get_registry

    driver = get_registry().open_device(dev)
    assert driver.description.mesh.n_nodes == 256


def test_no_devices_means_the_demo():
    assert HubConfig.from_dict({"hub": {"http_port": 0}}).demo


@pytest.mark.parametrize(("doc", "message"), [
    ({"hub": {"htp_port": 1}}, "[hub].htp_port: unknown key"),
    ({"hub": {"http_port": 70000}}, "[hub].http_port: a port number"),
    ({"hub": {"retention_days": -1}}, "[hub].retention_days: a positive number"),
    ({"hub": {"history": "yes"}}, "[hub].history: true or false"),
    ({"hubs": {}}, "unknown table [hubs]; did you mean [hub]?"),
    ({"device": [{"id": "a", "family": "scene"}, {"id": "a", "family": "scene"}]}, "device[1].id"),
    ({"device": [{"family": "scene"}]}, "device[0].id: required"),
    ({"device": [{"id": "hub", "family": "scene"}]}, "'hub' is the hub's own Thing"),
    ({"hub": {"history_skip": ["x"]}, "device": [{"id": "a", "family": "scene"}]}, "unknown device(s) ['x']"),
])
def test_mistakes_are_reported_with_their_place(doc, message):
    with pytest.raises(ConfigError) as e:
        HubConfig.from_dict(doc, source="hub.toml")
    assert message in str(e.value) and str(e.value).startswith("hub.toml")


def test_ws_port_false_turns_the_websocket_binding_off():
    assert HubConfig.from_dict({"hub": {"ws_port": False}}).ws_port is None


def test_unreadable_and_invalid_files(tmp_path):
    with pytest.raises(ConfigError, match="cannot read"):
        HubConfig.load(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[hub\n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        HubConfig.load(bad)


@pytest.mark.parametrize(("doc", "message"), [
    ({"hub": {"workers": 100000}},
     "hub.toml: [hub].workers: a whole number of processes (0: none), got 100000; must be from 0 to 64"),
    ({"hub": {"history_batch_ms": float("nan")}}, "hub.toml: [hub].history_batch_ms: a positive number of "
                                                  "milliseconds, got nan; must be above 0 and at most 60000"),
    ({"hub": {"retention_mb": float("inf")}}, "hub.toml: [hub].retention_mb: a positive number, got inf; "
                                              "must be above 0 and at most 1000000000"),
    ({"hub": {"ws_port": True}}, "hub.toml: [hub].ws_port: a port number (0: any free port), got True; "
                                 "must be from 0 to 65535"),
    ({"hub": {"name": " "}}, "hub.toml: [hub].name: a non-empty string, got ' '"),
    ({"hub": {"history_skip": ["a", 1]}}, "hub.toml: [hub].history_skip[1]: a device id, got 1"),
    ({"hub": []}, "hub.toml: [hub] must be a table, got []"),
])
def test_bounds_and_types_are_reported_in_one_line_with_their_place(doc, message):
    with pytest.raises(ConfigError) as e:
        HubConfig.from_dict(doc, source="hub.toml")
    assert str(e.value) == message


def test_the_config_error_is_the_hubs_one():
    from wott_hub import errors

    assert ConfigError is errors.ConfigError and errors.exit_code(ConfigError("x")) == 2
