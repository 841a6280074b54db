"""``[directory]`` and ``[discovery]`` in the hub config: defaults, values, and errors that name the key."""

from __future__ import annotations

import pytest

from wott_hub.config import ConfigError, HubConfig
from wott_hub.network import DirectoryConfig, DiscoveryConfig, Registration


def test_defaults_a_config_file_and_python():
    from_file = HubConfig.from_dict({"hub": {"name": "x"}})
    assert from_file.directory == DirectoryConfig(enabled=True, token=None, register_to=(), ttl_s=60.0)
    assert from_file.discovery.mdns and from_file.discovery.browse  # `wott-hub run` announces and browses
    assert HubConfig.demo_config().discovery == DiscoveryConfig()
    in_python = HubConfig()
    assert in_python.directory.enabled and not in_python.discovery.mdns and not in_python.discovery.browse


def test_every_key():
    cfg = HubConfig.from_dict({
        "directory": {"enabled": True, "token": " t ", "protect_reads": True, "ttl_s": 20,
                      "register_to": ["http://fleet:8090",
                                      {"url": "https://tdd.example/api/", "token": "u"}]},
        "discovery": {"mdns": False, "browse": True, "interfaces": ["192.168.1.4"],
                      "directories": ["http://other-hub:8080"], "adopt_hub_things": True},
    })
    assert cfg.directory == DirectoryConfig(
        True, "t", True, (Registration("http://fleet:8090/"), Registration("https://tdd.example/api/", "u")),
        20.0)
    assert cfg.discovery == DiscoveryConfig(False, True, ("192.168.1.4",), ("http://other-hub:8080/",), True)


@pytest.mark.parametrize(("data", "message"), [
    ({"directory": {"enable": True}}, "[directory].enable: unknown key (known: enabled, protect_reads"),
    ({"directory": {"enabled": "yes"}}, "[directory].enabled: true or false, got 'yes'"),
    ({"directory": {"ttl_s": 0}}, "[directory].ttl_s: a positive number of seconds, got 0"),
    ({"directory": {"token": ""}}, "[directory].token: a non-empty string"),
    ({"directory": {"register_to": "http://x/"}}, "[directory].register_to: a list of directory URLs"),
    ({"directory": {"register_to": ["ftp://x/"]}}, "[directory].register_to[0]: an http(s) URL, got 'ftp://x/'"),
    ({"directory": {"register_to": [{"url": "http://x/", "tok": "a"}]}},
     "[directory].register_to[0].tok: unknown key (known: token, url)"),
    ({"directory": {"protect_reads": True}}, "[directory].protect_reads: needs a token"),
    ({"discovery": {"mdns": 1}}, "[discovery].mdns: true or false, got 1"),
    ({"discovery": {"interfaces": "lo"}}, "[discovery].interfaces: a list of interface addresses"),
    ({"discovery": {"directories": ["nope"]}}, "[discovery].directories[0]: an http(s) URL, got 'nope'"),
    ({"discovery": []}, "[discovery] must be a table"),
])
def test_errors_name_the_table_and_key(data, message):
    with pytest.raises(ConfigError) as e:
        HubConfig.from_dict(data, source="hub.toml")
    assert str(e.value).startswith(f"hub.toml: {message}")


def test_the_example_config_file_loads():
    from pathlib import Path

    cfg = HubConfig.load(Path(__file__).resolve().parents[2] / "docs" / "hub.example.toml")
    assert cfg.directory.enabled and cfg.discovery.mdns


@pytest.mark.parametrize(("data", "message"), [
    ({"directory": {"ttl_s": 1e20}}, "[directory].ttl_s: a positive number of seconds, got 1e+20; "
                                     "must be from 1 to 86400"),
    ({"directory": {"ttl_s": float("nan")}}, "[directory].ttl_s: a positive number of seconds, got nan; "
                                             "must be from 1 to 86400"),
    ({"directory": {"register_to": [5]}}, "[directory].register_to[0]: an http(s) URL or a table "
                                          "{ url, token }, got 5"),
    ({"directory": {"register_to": [{"token": "t"}]}}, "[directory].register_to[0].url: required, missing"),
    ({"directory": {"register_to": [{"url": "http://x/", "token": ""}]}},
     "[directory].register_to[0].token: a non-empty string, got ''"),
    ({"discovery": {"interfaces": [""]}}, "[discovery].interfaces[0]: an interface address, got ''"),
    ({"directory": 3}, "[directory] must be a table, got 3"),
])
def test_every_error_is_one_line_naming_file_table_and_key(data, message):
    with pytest.raises(ConfigError) as e:
        HubConfig.from_dict(data, source="hub.toml")
    assert str(e.value) == f"hub.toml: {message}"


def test_ttl_bounds_hold_in_python_too():
    assert DirectoryConfig(ttl_s=1).ttl_s == 1 and DirectoryConfig(ttl_s=86_400).ttl_s == 86_400
    with pytest.raises(ConfigError, match=r"\[directory\]\.ttl_s: .* got 0\.5; must be from 1 to 86400"):
        DirectoryConfig(ttl_s=0.5)
