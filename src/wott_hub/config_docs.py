"""docs/configuration.md, generated from the declared config tables so the page cannot drift.

``python -m wott_hub.config_docs > docs/configuration.md`` writes it;
tests/hub/test_config.py fails when the committed page differs from what this
module renders from ``wott_hub.config.config_schema()``.
"""

from __future__ import annotations

import json
from typing import Any

from wott_hub.config import config_schema

__all__ = ["render"]

_HEAD = """# Configuration reference

Generated from the declared config tables (`wott_hub.config.config_schema()`,
`python -m wott_hub.config_docs > docs/configuration.md`); a test fails when this page
and the code disagree. docs/hub.md explains the settings; docs/hub.example.toml is a
commented example. Every key is optional. A key not listed here, a value of the wrong
type or out of its bounds is an error naming the file, table and key, e.g.
`hub.toml: [hub].workers: a whole number of processes (0: none), got 100000; must be from 0 to 64`.
NaN and infinities are refused everywhere (every number has an upper bound).

`[[device]]` tables take `id`, `family` and the family's settings: `wott-hub plugins families`
prints each family's JSON Schema, bounds included.
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
        if parts:
            return ", ".join(parts)
    return ""


def render() -> str:
    """The whole page: one table per config table, then the JSON Schema itself."""
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
    out.append("\n## JSON Schema\n\n```json\n" + json.dumps(schema, indent=2) + "\n```\n")
    return "\n".join(out)


if __name__ == "__main__":
    print(render(), end="")
