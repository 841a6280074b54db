"""Validate any TD against TD 1.1, the Tactile vocabulary and our interop rules,
and Tactile payloads against the schema their TD declares.

Every problem names the failing field by its JSON path, so a user can find it.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from typing import Any

import jsonschema
from wott_directory.validation import load_data, schema_problems

from wott_hub.tactile.device import NODE_UNITS

from .vocabulary import DETAIL_EVENTS, DETAIL_PROPERTIES, EVENTS, PROPERTIES, TD_CONTEXT

__all__ = ["Problem", "validate_payload", "validate_td"]

# TD-specific keywords that are not JSON Schema: dropped before payload validation
_TD_ONLY = ("forms", "@type", "title", "titles", "descriptions", "observable", "unit",
            "uriVariables", "readOnly", "writeOnly")


@dataclass(frozen=True, slots=True)
class Problem:
    rule: str  # "td-1.1" | "tactile" | "interop" | "payload"
    path: str  # JSON path of the failing field, e.g. $.properties.skinNodes.forms[0].op
    message: str

    def __str__(self) -> str:
        return f"[{self.rule}] {self.path}: {self.message}"


@cache
def td_schema_validator() -> jsonschema.protocols.Validator:
    schema = load_data("td-1.1-json-schema.json")  # the W3C schema shipped with wott_directory
    return jsonschema.Draft7Validator(schema, format_checker=jsonschema.Draft7Validator.FORMAT_CHECKER)


def _shape_schema(ds: dict[str, Any]) -> dict[str, Any]:
    """A schema that accepts data schemas declaring the same structure, types and units."""
    props: dict[str, Any] = {}
    required = []
    if "type" in ds:
        props["type"] = {"const": ds["type"]}
        required.append("type")
    if "unit" in ds:
        props["unit"] = {"const": ds["unit"]}
        required.append("unit")
    if "enum" in ds:
        props["enum"] = {"type": "array", "items": {"enum": ds["enum"]}}
    if "properties" in ds:
        props["properties"] = {
            "type": "object",
            "properties": {k: _shape_schema(v) for k, v in ds["properties"].items()},
            "required": list(ds.get("required", [])),
        }
        required.append("properties")
    if "items" in ds:
        props["items"] = _shape_schema(ds["items"])
        required.append("items")
    return {"type": "object", "properties": props, "required": required}


@cache
def tactile_validator() -> jsonschema.protocols.Validator:
    """The vocabulary's own schema for a TD: the affordances and their data shapes."""
    prop_schemas = {}
    for name, aff in PROPERTIES.items():
        s = _shape_schema(aff)
        if aff.get("observable"):
            s["properties"]["observable"] = {"const": True}
            s["required"].append("observable")
        prop_schemas[name] = s
    data = {name: _shape_schema(aff["data"]) for name, aff in EVENTS.items()}
    # a node's intensity is in its device's node unit (tactile.device.NodeSignal: mm, µT, counts, N)
    node = data["skinDeformedDetection"]["properties"]["properties"]["properties"]["arrayOfDeformedNodes"]
    intensity = node["properties"]["items"]["properties"]["properties"]["properties"]["deformedNodeIntensity"]
    intensity["properties"]["unit"] = {"enum": sorted(set(NODE_UNITS.values()))}
    event_schemas = {name: {"type": "object", "properties": {"data": d}, "required": ["data"]}
                     for name, d in data.items()}
    schema = {
        "type": "object",
        "properties": {
            "properties": {"type": "object", "properties": prop_schemas,
                           "required": [p for p in PROPERTIES if p not in DETAIL_PROPERTIES]},
            "events": {"type": "object", "properties": event_schemas,
                       "required": [e for e in EVENTS if e not in DETAIL_EVENTS]},
        },
        "required": ["properties", "events"],
    }
    return jsonschema.Draft7Validator(schema)


def _problems(validator: jsonschema.protocols.Validator, doc: Any, rule: str) -> list[Problem]:
    return [Problem(rule, path, message)
            for path, message in schema_problems(validator, doc, join=_dotted)]


def _dotted(path: str, key: str) -> str:
    """A missing member's path as ``td validate`` has always printed it: ``$.a.@context``, where
    the directory's problem+json writes ``$.a["@context"]``."""
    return f"{path}.{key}"


def _interop_problems(td: dict[str, Any]) -> list[Problem]:
    """Rules that make node-wot and wotpy clients accept our TDs (DESIGN.md section 2)."""
    out = []
    ctx = td.get("@context")
    if not (isinstance(ctx, list) and ctx[:2] == TD_CONTEXT):
        out.append(Problem("interop", "$['@context']",
                           f"must be an array starting with {TD_CONTEXT} (node-wot needs v1 first)"))
    for kind in ("properties", "actions", "events"):
        affordances = td.get(kind)
        if not isinstance(affordances, dict):  # a wrong type is the TD schema's problem, reported there
            continue
        for name, aff in affordances.items():
            base = f"$.{kind}.{name}"
            _find_empty_keywords(aff, base, out)
            _find_untyped(aff, kind, base, out)
            forms = aff.get("forms") if isinstance(aff, dict) else None
            for i, form in enumerate(forms if isinstance(forms, list) else []):
                if not isinstance(form, dict):
                    continue
                where = f"{base}.forms[{i}]"
                if "op" not in form:
                    out.append(Problem("interop", f"{where}.op", "every form must state its op"))
                href = str(form.get("href", ""))
                if "://" in href and not href.startswith(("http://", "https://", "ws://", "wss://")):
                    continue  # another protocol's form (mqtt://, the MQTT binding's terms): not HTTP's rules
                if str(form.get("href", "")).startswith(("http", "things/", "/")) or "base" in td:
                    # a long poll leaves it to the binding's default (GET): node-wot 0.9.2 sends its
                    # handshake with the declared method, a HEAD only when none is (security/policy.py)
                    if "htv:methodName" not in form and form.get("subprotocol") not in (
                            "websocket", "longpoll"):
                        if not str(form.get("href", "")).startswith("ws"):
                            out.append(Problem("interop", f"{where}['htv:methodName']",
                                               "HTTP forms must state htv:methodName"))
                if kind == "events" and "subprotocol" not in form and not str(
                    form.get("href", "")).startswith("ws"):
                    out.append(Problem("interop", f"{where}.subprotocol",
                                       "event forms over HTTP must state their subprotocol"))
    return out


_SCHEMAS_OF = {"properties": ((),), "actions": (("input",), ("output",)), "events": (("data",),)}


def _find_untyped(aff: Any, kind: str, path: str, out: list[Problem]) -> None:
    """Every data schema wotpy builds (an affordance's, its object members, array items) states its
    ``type``: wotpy 0.18 cannot consume one without (``ValueError: Unknown type: None``)."""
    if not isinstance(aff, dict):
        return
    for keys in _SCHEMAS_OF[kind]:
        node: Any = aff
        for key in keys:
            node = node.get(key) if isinstance(node, dict) else None
        if node is not None:
            _check_typed(node, ".".join([path, *keys]), out)


def _check_typed(node: Any, path: str, out: list[Problem]) -> None:
    if not isinstance(node, dict):
        return
    if "type" not in node:
        out.append(Problem("interop", f"{path}.type", "a data schema must state its type (wotpy needs one)"))
    members = node.get("properties")
    for name, sub in (members.items() if isinstance(members, dict) else ()):
        _check_typed(sub, f"{path}.properties.{name}", out)
    items = node.get("items")
    for i, sub in enumerate(items if isinstance(items, list) else [items] if items is not None else []):
        _check_typed(sub, f"{path}.items" + (f"[{i}]" if isinstance(items, list) else ""), out)


def _find_empty_keywords(node: Any, path: str, out: list[Problem]) -> None:
    if isinstance(node, dict):
        for k, v in node.items():
            if k in ("oneOf", "anyOf", "allOf", "enum") and v == []:
                out.append(Problem("interop", f"{path}.{k}", "empty keyword: not valid JSON Schema"))
            elif k != "forms":
                _find_empty_keywords(v, f"{path}.{k}", out)
    elif isinstance(node, list):
        for i, v in enumerate(node):
            _find_empty_keywords(v, f"{path}[{i}]", out)


def validate_td(td: Any, *, tactile: bool = True, interop: bool = True) -> list[Problem]:
    """All problems of a TD document; empty when it is valid."""
    if not isinstance(td, dict):
        return [Problem("td-1.1", "$", f"a TD must be a JSON object, got {type(td).__name__}")]
    problems = _problems(td_schema_validator(), td, "td-1.1")
    if tactile:
        problems += _problems(tactile_validator(), td, "tactile")
    if interop:
        problems += _interop_problems(td)
    return problems


def affordance_schema(td: dict[str, Any], kind: str, name: str) -> dict[str, Any]:
    """The JSON Schema a TD declares for a property value or an event's data."""
    aff = td[{"property": "properties", "event": "events"}[kind]][name]
    ds = aff.get("data", {}) if kind == "event" else aff
    schema: dict[str, Any] = _strip_td_keywords(ds)
    return schema


def _strip_td_keywords(ds: Any) -> Any:
    if isinstance(ds, dict):
        return {k: _strip_td_keywords(v) for k, v in ds.items() if k not in _TD_ONLY}
    if isinstance(ds, list):
        return [_strip_td_keywords(v) for v in ds]
    return ds


def validate_payload(td: dict[str, Any], kind: str, name: str, value: Any) -> list[Problem]:
    """Problems of a property value or event payload against the schema its TD declares."""
    validator = jsonschema.Draft7Validator(affordance_schema(td, kind, name))
    return _problems(validator, value, "payload")
