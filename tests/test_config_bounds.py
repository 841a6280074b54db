"""Every numeric setting has bounds checked at load (issue 16 item 8), errors name file, table and key,
the CLI reports a bad config in one line, and docs/configuration.md is the schema the code declares."""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
from pathlib import Path
from typing import Annotated

import pytest

from wott_hub.config import MAX_WORKERS, ConfigError, HubConfig, check_port, config_schema
from wott_hub.errors import ConfigError as RootConfigError
from wott_hub.errors import WottHubError
from wott_hub.plugin_api import Meta, SettingsModel

ROOT = Path(__file__).resolve().parents[1]

# key, a value just inside the bounds, values outside them (NaN and infinities everywhere they parse)
HUB_BOUNDS = [
    ("workers", MAX_WORKERS, [-1, MAX_WORKERS + 1, 100_000], "from 0 to 64"),
    ("history_batch_ms", 60_000, [0, -5, 60_000.5, 1e300, math.nan, math.inf], "above 0 and at most 60000"),
    ("history_batch_max", 1_000_000, [0, 1_000_001], "from 1 to 1000000"),
    ("retention_days", 36_500, [0, -1, 36_501, math.inf, math.nan], "above 0 and at most 36500"),
    ("retention_mb", 1e9, [0, 2e9, math.inf, math.nan], "above 0 and at most 1000000000"),
    ("ring_size", 10_000_000, [0, 10_000_001], "from 1 to 10000000"),
    ("max_pending", 100_000_000, [0, 100_000_001], "from 1 to 100000000"),
    ("heartbeat_s", 3600, [0, 3601, math.inf, -math.inf, math.nan], "above 0 and at most 3600"),
    ("http_port", 65535, [-1, 65536, 70000], "from 0 to 65535"),
    ("ws_port", 0, [-1, 65536], "from 0 to 65535"),
    ("catalogue_port", 65535, [70000], "from 0 to 65535"),
]


@pytest.mark.parametrize(("key", "ok", "bad", "bounds"), HUB_BOUNDS, ids=[b[0] for b in HUB_BOUNDS])
def test_hub_numbers_are_bounded(key, ok, bad, bounds):
    assert getattr(HubConfig.from_dict({"hub": {key: ok}}), key) == ok
    for value in bad:
        with pytest.raises(ConfigError) as e:
            HubConfig.from_dict({"hub": {key: value}}, source="hub.toml")
        msg = str(e.value)
        assert msg.startswith(f"hub.toml: [hub].{key}: ") and f"got {value!r}" in msg, msg
        assert msg.endswith(f"must be {bounds}"), msg
        assert "\n" not in msg


def test_the_issue_examples_word_for_word():
    cases = {
        "workers": (100_000, "hub.toml: [hub].workers: a whole number of processes (0: none), got 100000; "
                             "must be from 0 to 64"),
        "history_batch_ms": (1e300, "hub.toml: [hub].history_batch_ms: a positive number of milliseconds, "
                                    "got 1e+300; must be above 0 and at most 60000"),
        "retention_days": (math.inf, "hub.toml: [hub].retention_days: a positive number, got inf; "
                                     "must be above 0 and at most 36500"),
    }
    for key, (value, message) in cases.items():
        with pytest.raises(ConfigError) as e:
            HubConfig.from_dict({"hub": {key: value}}, source="hub.toml")
        assert str(e.value) == message


@pytest.mark.parametrize(("ttl", "ok"), [(1, True), (86_400, True), (0.5, False), (86_401, False),
                                          (1e20, False), (math.nan, False), (math.inf, False)])
def test_registration_ttl_is_bounded(ttl, ok):
    doc = {"directory": {"ttl_s": ttl}}
    if ok:
        assert HubConfig.from_dict(doc).directory.ttl_s == ttl
        return
    with pytest.raises(ConfigError, match=r"^hub\.toml: \[directory\]\.ttl_s: a positive number of seconds, "
                                          r"got .*; must be from 1 to 86400$"):
        HubConfig.from_dict(doc, source="hub.toml")


def test_one_config_error_class_for_the_hub():
    assert ConfigError is RootConfigError and issubclass(ConfigError, WottHubError)
    assert issubclass(ConfigError, ValueError)  # `except ValueError` written before the tree still works


def test_values_built_in_python_or_replaced_are_checked_too():
    with pytest.raises(ConfigError, match=r"\[hub\]\.workers: .*got 100000"):
        HubConfig(workers=100_000)
    with pytest.raises(ConfigError, match=r"^hub\.toml: \[hub\]\.http_port: .*got 70000"):
        dataclasses.replace(HubConfig(source="hub.toml"), http_port=70_000)
    from wott_hub.network import DirectoryConfig

    with pytest.raises(ConfigError, match=r"\[directory\]\.ttl_s: .*got 1e\+20"):
        DirectoryConfig(ttl_s=1e20)


def test_cli_port_check_names_the_option():
    assert check_port(0) == 0 and check_port(65535) == 65535 and check_port(None) is None
    with pytest.raises(ConfigError, match=r"^--ws-port: a port number .*got 70000; must be from 0 to 65535$"):
        check_port(70_000, "--ws-port")


def _cli(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    exe = Path(sys.executable).parent / "wott-hub"
    return subprocess.run([str(exe), *args], capture_output=True, text=True, timeout=60, cwd=cwd)


@pytest.mark.parametrize(("toml", "expected"), [
    ("[hub]\nworkers = 100000\n", "[hub].workers: a whole number of processes (0: none), got 100000"),
    ("[hub]\nhistory_batch_ms = nan\n", "[hub].history_batch_ms: a positive number of milliseconds, got nan"),
    ("[directory]\nttl_s = 1e20\n", "[directory].ttl_s: a positive number of seconds, got 1e+20"),
    ("[hub\n", "not valid TOML"),
])
def test_cli_reports_a_bad_config_in_one_line(tmp_path, toml, expected):
    bad = tmp_path / "bad.toml"
    bad.write_text(toml)
    done = _cli("run", "--config", str(bad), cwd=tmp_path)
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {bad}") and expected in lines[0], done.stderr
    assert "Traceback" not in done.stderr + done.stdout


def test_cli_refuses_a_port_out_of_range(tmp_path):
    done = _cli("run", "--port", "70000", cwd=tmp_path)
    assert done.returncode == 2
    assert done.stderr.strip() == "error: --port: a port number (0: any free port), got 70000; " \
                                  "must be from 0 to 65535"


def test_the_committed_configuration_doc_is_the_generated_one():
    from wott_hub.config_docs import render

    committed = (ROOT / "docs" / "configuration.md").read_text()
    assert committed == render(), "docs/configuration.md is stale: python -m wott_hub.config_docs > it"


def test_the_schema_accepts_the_documented_example_and_carries_every_bound():
    import tomllib

    import jsonschema

    schema = config_schema()
    jsonschema.Draft202012Validator.check_schema(schema)
    example = tomllib.loads((ROOT / "docs" / "hub.example.toml").read_text())
    jsonschema.Draft202012Validator(schema).validate(example)
    hub = schema["$defs"]["hub"]["properties"]
    for key, *_ in HUB_BOUNDS:
        numbers = [hub[key], *hub[key].get("anyOf", [])]
        assert any("maximum" in p for p in numbers), key  # every number has an upper bound
    assert schema["$defs"]["directory"]["properties"]["ttl_s"]["maximum"] == 86_400


def test_config_modules_import_no_heavy_library_and_no_cycle():
    code = ("import sys; import wott_hub.network.config, wott_hub.config; "
            "print(sorted(m for m in ('scipy', 'wotpy', 'sqlalchemy', 'tornado', 'zeroconf', 'jsonschema') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and out.stdout.strip() == "[]", out.stderr
    src = (ROOT / "src" / "wott_hub" / "network" / "config.py").read_text()
    assert "wott_hub.config " not in src and "from wott_hub.config import" not in src


def test_only_the_hubs_configspec_reads_through_wott_configspec():
    """Every hub module reads its tables through ``wott_hub.configspec``: its errors are the hub's."""
    import ast

    importers = []
    for path in sorted((ROOT / "src" / "wott_hub").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ""] if isinstance(node, ast.ImportFrom) else []
            if any(n == "wott_configspec" or n.startswith("wott_configspec.") for n in names):
                importers.append(str(path.relative_to(ROOT)))
    assert sorted(set(importers)) == ["src/wott_hub/configspec.py"]


# -- the directory's own settings (its own distribution, its own single ConfigError) ---------------

@pytest.mark.parametrize(("key", "value", "message"), [
    ("page_size", 0, "page_size: a whole number, got 0; must be from 1 to 10000"),
    ("max_body_bytes", 10, "max_body_bytes: a whole number, got 10; must be from 1024 to 1073741824"),
    ("purge_interval", math.nan, "purge_interval: a number, got nan; must be above 0 and at most 3600"),
    ("sse_keepalive", math.inf, "sse_keepalive: a number, got inf; must be above 0 and at most 3600"),
    ("sse_queue", 0, "sse_queue: a whole number, got 0; must be from 1 to 10000000"),
    ("event_retention", -1, "event_retention: a whole number, got -1; must be from 0 to 10000000"),
    ("max_query_length", 10**7, "max_query_length: a whole number, got 10000000; must be from 1 to 1000000"),
    ("freeze_every", 0, "freeze_every: a whole number, got 0; must be from 1 to 10000000"),
])
def test_directory_settings_are_bounded(key, value, message):
    from wott_directory import ConfigError as DirectoryConfigError
    from wott_directory import DirectorySettings

    with pytest.raises(DirectoryConfigError) as e:
        DirectorySettings(**{key: value})
    assert str(e.value) == message


def test_the_hub_translates_the_directory_error_once():
    from wott_hub.network.config import embedded_directory_settings

    assert embedded_directory_settings(token="t", page_size=5).page_size == 5
    with pytest.raises(ConfigError, match=r"^\[directory\]: page_size: a whole number, got 0"):
        embedded_directory_settings(page_size=0)


# -- family settings: a model class through the same hook, JSON Schema still emitted -----------------

class GaugeSettings(SettingsModel):  # module level: msgspec resolves the annotations in the module
    gain: Annotated[float, Meta(gt=0, le=100, description="Counts to kPa.")] = 1.0
    channels: Annotated[int, Meta(ge=1, le=64)] = 8


def _model_plugin_registry():
    from wott_hub.plugin_api import DeviceConfig, FamilyInfo, hookimpl
    from wott_hub.plugins.registry import Registry

    class GaugePlugin:
        opened: list[DeviceConfig] = []

        @hookimpl
        def wott_hub_families(self):
            return [FamilyInfo("gauge", "a family declared as a settings model", GaugeSettings)]

        @hookimpl
        def wott_hub_open_device(self, config):
            self.opened.append(config)
            from wott_hub.plugin_api import DriverError

            raise DriverError("no hardware here")  # what reached the plugin is what is asserted

    reg = Registry(entry_points=False, builtins=False)
    plugin = GaugePlugin()
    reg.register(plugin, "gauge-plugin")
    return reg, plugin, DeviceConfig


def test_a_family_may_declare_its_settings_as_a_model():
    reg, plugin, DeviceConfig = _model_plugin_registry()
    schema = reg.families()["gauge"].schema
    assert schema["properties"]["gain"] == {"description": "Counts to kPa.", "type": "number",
                                            "exclusiveMinimum": 0, "maximum": 100, "default": 1.0}
    assert schema["additionalProperties"] is False and reg.plugins()[0].error is None
    with pytest.raises(Exception, match="no hardware here"):
        reg.open_device(DeviceConfig("g", "gauge", {"gain": 2}))
    assert plugin.opened[-1].settings == {"gain": 2.0, "channels": 8}  # checked, defaults filled in
    for settings, message in [({"gain": 1e300}, "setting 'gain': 1e+300 is greater than the maximum of 100"),
                              ({"gain": math.nan}, "setting 'gain': a number, got nan; must be above 0"),
                              ({"gain": -math.inf}, "setting 'gain': -inf is less than or equal to"),
                              ({"channels": 0}, "setting 'channels': 0 is less than the minimum of 1"),
                              ({"gane": 1}, "setting 'gane': unknown setting")]:
        with pytest.raises(Exception) as e:
            reg.open_device(DeviceConfig("g", "gauge", settings))
        assert str(e.value).startswith(f"device 'g' (family 'gauge'): {message}"), str(e.value)


def test_schema_families_refuse_nan_and_infinity_too():
    from wott_hub.plugin_api import DeviceConfig, DriverError
    from wott_hub.plugins import get_registry

    reg = get_registry()
    for settings, message in [
        ({"simulate": True, "kpa_per_count": 1e300}, "setting 'kpa_per_count': 1e+300 is greater than"),
        ({"simulate": True, "kpa_per_count": math.nan}, "setting 'kpa_per_count': a number, got nan"),
        ({"simulate": True, "rate_hz": math.inf}, "setting 'rate_hz': inf is greater than the maximum"),
    ]:
        with pytest.raises(DriverError) as e:
            reg.open_device(DeviceConfig("t", "taxel-array", settings))
        assert str(e.value).startswith(f"device 't' (family 'taxel-array'): {message}"), str(e.value)
    with pytest.raises(DriverError, match=r"^device 's' \(family 'scene'\): setting 'rate_hz': a finite "
                                          r"number, got nan"):
        reg.open_device(DeviceConfig("s", "scene", {"step": [{"kind": "press"}], "rate_hz": math.nan}))
    with pytest.raises(DriverError, match=r"setting 'rate_hz': 1e\+300 is greater than the maximum of 10000"):
        reg.open_device(DeviceConfig("s", "scene", {"step": [{"kind": "press"}], "rate_hz": 1e300}))


def test_a_number_whose_schema_declares_no_maximum_is_still_bounded():
    from wott_hub.plugin_api import DriverError
    from wott_hub.plugins.dict_schema import with_defaults

    schema = {"properties": {
        "x": {"type": "number"}, "xs": {"type": "array", "items": {"type": "number"}},
        "t": {"type": "object", "properties": {"y": {"type": "number", "maximum": 1e12}}}}}
    assert with_defaults(schema, {"x": 1e9, "xs": [-1e9], "t": {"y": 1e12}})["x"] == 1e9
    for settings, message in [({"x": 1e300}, "setting 'x': got 1e+300; must be at most 1e+09 in magnitude"),
                              ({"xs": [1.0, -math.inf]}, "setting 'xs[1]': a finite number, got -inf"),
                              ({"t": {"y": math.nan}}, "setting 't.y': a finite number, got nan")]:
        with pytest.raises(DriverError) as e:
            with_defaults(schema, settings)
        assert str(e.value) == message


def _numbers(schema, path=""):
    """(path, property) of every ``number`` in a settings schema, nested tables and lists included."""
    if not isinstance(schema, dict):
        return
    types = schema.get("type")
    if types == "number" or (isinstance(types, list) and "number" in types):
        yield path, schema
    for key, sub in (schema.get("properties") or {}).items():
        yield from _numbers(sub, f"{path}.{key}" if path else key)
    if isinstance(schema.get("items"), dict):
        yield from _numbers(schema["items"], f"{path}[]")
    for alt in schema.get("oneOf", []) + schema.get("anyOf", []):
        yield from _numbers(alt, path)


def test_every_number_setting_of_every_first_party_family_declares_its_bounds():
    from wott_hub.plugins import get_registry

    families = get_registry().families()
    assert {"scene", "wot-remote", "taxel-array", "barrel-vision", "flat-vision"} <= set(families)
    unbounded = [f"{name}: {path}" for name, fam in families.items() for path, prop in _numbers(fam.schema)
                 if "maximum" not in prop and "exclusiveMaximum" not in prop]
    assert unbounded == []


def test_the_taxel_model_is_read_directly_too():
    from wott_driver_taxel.plugin import PRESETS, TaxelSettings, open_taxel_device

    from wott_hub.plugin_api import DeviceConfig, DriverError, read_settings

    s = read_settings(TaxelSettings, {"port": "/dev/ttyUSB0"})
    assert (s.rows, s.kpa_per_count, s.backoff_cap_s) == (None, 0.01, 5.0)  # rows: the protocol's
    assert (PRESETS[s.protocol].rows, PRESETS["flexitac"].cols) == (16, 32)
    with pytest.raises(DriverError, match=r"setting 'kpa_per_count': a number, got 1e\+300; "
                                          r"must be above 0 and at most 10$"):
        open_taxel_device(DeviceConfig("t", "taxel-array", {"simulate": True, "kpa_per_count": 1e300}))
