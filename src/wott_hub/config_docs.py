"""docs/configuration.md, generated from the declared config tables so the page cannot drift.

``python -m wott_hub.config_docs > docs/configuration.md`` writes it;
tests/test_config_bounds.py fails when the committed page differs from what this module
renders from ``wott_hub.config.config_schema()`` and from the settings models of the
first-party device families (``FIRST_PARTY``: the built-in ones and the six plugins of
``plugins/``). Each family gets the table of its settings (``settings_rows``: nested tables
flattened to ``optics.focal_px``, what ``wott-hub plugins families NAME`` prints too), the
rules across settings its schema states, and a complete ``[[device]]`` example
(``DEVICE_EXAMPLES``) that tests/cli/test_config_docs.py checks as ``wott-hub config check``
does. Another plugin's family is not on the page (it depends on what is installed):
``wott-hub plugins families`` shows it.
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any

from wott_hub.config import config_schema

__all__ = ["DEVICE_EXAMPLES", "FIRST_PARTY", "SettingRow", "family_rules", "render", "settings_rows"]

FIRST_PARTY = ("builtin", "barrel", "flatpad", "taxel", "anyskin", "xela", "gel")
"""The plugins whose families the page documents: the hub's own and those of ``plugins/``."""

DEVICE_EXAMPLES: dict[str, str] = {
    "scene": '''\
[[device]]
id = "finger-1"
family = "scene"                  # no hardware: a scripted scene on an example skin
title = "Finger pad (scene)"
shape = "flat"                    # barrel, flat or cylinder
rate_hz = 120
loop = true
material = "ecoflex-00-30"

[[device.step]]                   # or scene = "press.toml" (docs/scenes.md)
kind = "press"
at = [11.25, 11.25, 4.0]
start_s = 0.5
duration_s = 1.0
depth_mm = 1.0
radius_mm = 4.0

[[device.step]]
kind = "slide"
at = [5.0, 5.0, 4.0]
to = [17.0, 17.0, 4.0]
start_s = 2.0
duration_s = 1.5
depth_mm = 0.8
''',
    "wot-remote": '''\
[[device]]
id = "remote-palm"
family = "wot-remote"             # a tactile device that speaks WoT itself (another hub's, say)
url = "http://palm.local:8080/wot/palm"   # its Tactile TD
token = "wott_0123abcd_a-read-token-of-that-hub"   # if it asks for one
timeout_s = 10
''',
    "barrel-vision": '''\
[[device]]
id = "arm-skin"
family = "barrel-vision"          # TacLink-style barrel: two fisheye cameras (docs/barrel-vision.md)
title = "Forearm skin"
source = [0, 1]                   # [bottom, top]: camera indices, files or URLs; "sim": the simulator
fps = 60
reference = "first-frame"         # learn the dots at rest from the first frames
model = "models/my-taclink.onnx"  # optional: your own displacement model
cameras = { f_px = 234.0, offset_mm = 6.0 }
''',
    "flat-vision": '''\
[[device]]
id = "pad-left"
family = "flat-vision"            # GelSight/DIGIT-style pad, one camera (docs/flat-pad.md)
source = 0                        # /dev/video0; "sim": the simulator
rows = 9
cols = 11
pitch_mm = 2.0
marker_radius_mm = 0.45
depth_model = "pad-left-depth.json"
optics = { focal_px = 470.0, air_gap_mm = 18.5 }
''',
    "taxel-array": '''\
[[device]]
id = "left-palm"
family = "taxel-array"            # rows x cols pressure cells on a serial port (docs/taxel-protocol.md)
port = "/dev/ttyUSB0"             # or COM3, socket://10.0.0.7:4000; simulate = true: no board needed
baudrate = 921600
protocol = "binary"               # or "ascii"; "flexitac", "3dvitac": their makers' formats (docs/skins.md)
rows = 16
cols = 16
pitch_mm = 4.0
material = "ecoflex-00-30"
thickness_mm = 3.0
kpa_per_count = 0.01
epsilon_mm = 0.05
''',
    "anyskin": '''\
[[device]]
id = "fingertip"
family = "anyskin"                # AnySkin or ReSkin magnetic skin (docs/skins.md)
port = "/dev/ttyACM0"             # the QT Py / Trinket; simulate = true: no board needed
board = "anyskin"                 # or "reskin"
epsilon_ut = 30.0
baseline_samples = 5
''',
    "xela": '''\
[[device]]
id = "xela-index"
family = "xela"                   # one position of a running xela_server (docs/skins.md)
url = "ws://127.0.0.1:5000"
position = 1
model = "uSPa46"
forces = false                    # true: the server's calibrated forces, N
''',
    "gelsight-mini": '''\
[[device]]
id = "mini-left"
family = "gelsight-mini"          # a GelSight Mini (docs/gel.md)
source = "sessions/mini.avi"      # a recording; or device = "/dev/video2", or serial = "28F5K4RR"
realtime = false                  # as fast as processed
rest_frames = 5
''',
    "digit": '''\
[[device]]
id = "digit-right"
family = "digit"                  # a DIGIT (docs/gel.md)
serial = "D20001"                 # its /dev/videoN found through udev (not tried on hardware)
stream = "QVGA60"
led = [15, 15, 15]
''',
}
"""A complete ``[[device]]`` table per first-party family, as docs/configuration.md shows it."""

_HEAD = """# Configuration reference

Generated from the declared config tables (`wott_hub.config.config_schema()`) and the
first-party device families' settings models (`python -m wott_hub.config_docs >
docs/configuration.md`); a test fails when this page and the code disagree, and another
checks every example below as `wott-hub config check` does. docs/hub.md explains the
settings; docs/hub.example.toml is a commented example. Every key is optional. A key not
listed here, a value of the wrong type or out of its bounds is an error naming the file,
table and key, e.g.
`hub.toml: [hub].workers: a whole number of processes (0: none), got 100000; must be from 0 to 64`;
a misspelt key says which one it probably is (`hub.toml: device[0].simulte (device 'pad',
family 'taxel-array'): unknown setting; did you mean 'simulate'?`).
NaN and infinities are refused everywhere (every number has an upper bound).

`wott-hub config check --config hub.toml` lists every problem of a config at once without
starting anything (`--open` also opens each device and closes it); `wott-hub run` refuses
to start on any of them.

Without a config, `wott-hub run` serves the demo fleet with `retention_mb = 500`: its
database (`wott-hub.db` in the working folder) stays under 500 MB, the oldest events
deleted first. A config file keeps everything unless it sets `retention_mb` or
`retention_days`.
"""


def _type(prop: dict[str, Any]) -> str:
    if "anyOf" in prop:
        return " or ".join(_type(p) for p in prop["anyOf"])
    if "$ref" in prop:
        return "table"
    if "const" in prop:
        return json.dumps(prop["const"])
    if "enum" in prop:
        return " or ".join(json.dumps(v) for v in prop["enum"])
    t = prop.get("type", "any")
    if t == "array":
        return f"list of {_type(prop.get('items', {}))}"
    if t == "object":
        return "table"
    return str(t)


def _bounds(prop: dict[str, Any]) -> str:
    for p in prop.get("anyOf", [prop]):
        parts = []
        for key, sign in (("minimum", "≥"), ("exclusiveMinimum", ">"), ("maximum", "≤"),
                          ("exclusiveMaximum", "<")):
            if key in p:
                parts.append(f"{sign} {p[key]:g}" if isinstance(p[key], float) else f"{sign} {p[key]}")
        if "pattern" in p:
            parts.append("not blank" if p["pattern"] == r"\S" else f"matches `{p['pattern']}`")
        if "minItems" in p and p.get("minItems") == p.get("maxItems"):
            parts.append(f"{p['minItems']} items")
        if parts:
            return ", ".join(parts)
    return ""


@dataclass(frozen=True)
class SettingRow:
    """One setting of a family: its key (``optics.focal_px`` inside a nested table), type,
    default (``"required"`` for one the family requires), bounds and meaning."""

    key: str
    type: str
    default: str
    bounds: str
    meaning: str


def settings_rows(schema: Mapping[str, Any]) -> list[SettingRow]:
    """A family's settings schema (``FamilyInfo.schema``) as rows, nested tables flattened."""
    return list(_rows(schema, ""))


def _rows(schema: Mapping[str, Any], prefix: str) -> Iterator[SettingRow]:
    required = set(schema.get("required") or ())
    for key, prop in (schema.get("properties") or {}).items():
        name = f"{prefix}{key}"
        given = "default" in prop and not isinstance(prop["default"], dict)  # a table's: on its rows
        default = "required" if key in required else json.dumps(prop["default"]) if given else ""
        yield SettingRow(name, _type(prop), default, _bounds(prop), prop.get("description", ""))
        if prop.get("type") == "object" and prop.get("properties"):
            yield from _rows(prop, f"{name}.")
        items = prop.get("items")
        if prop.get("type") == "array" and isinstance(items, Mapping) and items.get("properties"):
            yield from _rows(items, f"{name}[].")


def family_rules(schema: Mapping[str, Any]) -> list[str]:
    """The rules across settings a family's schema states, in words (the two forms the families
    use: one of several keys, a key required unless a flag is set)."""
    rules = []
    alternatives = schema.get("oneOf") or []
    names = [a["required"][0] for a in alternatives
             if isinstance(a, Mapping) and len(a.get("required") or ()) == 1]
    if names and len(names) == len(alternatives):
        rules.append("exactly one of " + " or ".join(f"`{n}`" for n in names))
    cond, then = schema.get("if"), schema.get("then")
    if isinstance(cond, Mapping) and isinstance(then, Mapping) and set(cond) == {"not"}:
        neg = cond["not"]
        props = neg.get("properties") or {}
        flags = [k for k, v in props.items() if isinstance(v, Mapping) and "const" in v]
        needed = then.get("required") or []
        if flags and needed:
            flag = flags[0]
            value = json.dumps(neg["properties"][flag]["const"])
            rules.append(f"{', '.join(f'`{n}`' for n in needed)} required unless `{flag} = {value}`")
    return rules


def _families() -> list[Any]:
    from wott_hub.plugins import get_registry

    fams = get_registry().families().values()
    return sorted((f for f in fams if f.plugin in FIRST_PARTY), key=lambda f: (f.plugin != "builtin", f.name))


def _family_section(fam: Any) -> list[str]:
    out = [f"\n### `family = \"{fam.name}\"`\n", f"{fam.description} (plugin `{fam.plugin}`)\n"]
    rules = family_rules(fam.schema)
    if rules:
        out.append("Rules: " + "; ".join(rules) + ".\n")
    out.append("| key | type | default | bounds | meaning |\n|---|---|---|---|---|")
    for r in settings_rows(fam.schema):
        cells = [f"`{r.key}`", r.type, f"`{r.default}`" if r.default else "", r.bounds, r.meaning]
        out.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    example = DEVICE_EXAMPLES.get(fam.name)
    if example:
        out.append(f"\nExample:\n\n```toml\n{example}```")
    return out


def render() -> str:
    """The whole page: one table per config table, each family's settings and example, then the
    JSON Schema itself."""
    schema = config_schema()
    out = [_HEAD]
    for table, ref in schema["properties"].items():
        if "$ref" not in ref:
            continue
        name = ref["$ref"].rsplit("/", 1)[-1]
        props = schema["$defs"][name]["properties"]
        out.append(f"\n## [{table}]\n\n| key | type | default | bounds | meaning |\n|---|---|---|---|---|")
        for key, prop in props.items():
            default = json.dumps(prop["default"]) if "default" in prop else "(none)"
            desc = prop.get("description", "").replace("|", "\\|")
            out.append(f"| `{key}` | {_type(prop)} | `{default}` | {_bounds(prop)} | {desc} |")
    out.append("\n## [[device]]\n\n`id` (unique; not `hub`) and `family`; every other key is a setting of "
               "the family, listed below for the families that come with wott-hub (another plugin's: "
               "`wott-hub plugins families NAME`).")
    for fam in _families():
        out += _family_section(fam)
    out.append("\n## JSON Schema\n\n```json\n" + json.dumps(schema, indent=2) + "\n```\n")
    return "\n".join(out)


if __name__ == "__main__":
    print(render(), end="")
