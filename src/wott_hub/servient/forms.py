"""What the servient does to TDs besides writing their forms (``wott_hub.td.forms``):
re-serving a TD under this hub's layout, and removing what wotpy writes that clients reject.
"""

from __future__ import annotations

import copy
from typing import Any, TypeVar

from wott_hub.td.forms import PREFIX, FormLayout
from wott_hub.td.raw import RAW_TYPES

__all__ = ["PREFIX", "FormLayout", "clean_td", "with_forms"]


def with_forms(td: dict[str, Any], thing: str, layout: FormLayout) -> dict[str, Any]:
    """A copy of ``td`` whose forms and ``base`` are this hub's (e.g. a recorded TD, re-served). A raw
    signal's property (``td.raw``) is left out: it is the live device's, nothing of it is recorded."""
    out = copy.deepcopy(td)
    props = out.get("properties")
    if isinstance(props, dict):
        for name in [n for n, a in props.items() if isinstance(a, dict) and a.get("@type") in RAW_TYPES]:
            del props[name]
    factory = layout.factory(thing)
    for kind, key in (("property", "properties"), ("event", "events")):
        for name, aff in (out.get(key) or {}).items():
            aff["forms"] = factory(kind, name, aff)
    out["forms"] = layout.thing_forms(thing)
    out["base"] = f"{layout.http_base}/"
    if layout.mqtt is not None:  # its forms use the binding template's mqv: terms
        layout.mqtt.add_context(out)
    _current_units(out)
    return clean_td(out)


# units renamed in the Tactile context (a term may not contain "/" in JSON-LD 1.1): a TD recorded
# before (a replay of an older recording) is served with the current name
_RENAMED_UNITS = {"mm/s": "mm.s-1"}


def _current_units(node: Any) -> None:
    if isinstance(node, dict):
        unit = node.get("unit")
        if isinstance(unit, str) and unit in _RENAMED_UNITS:
            node["unit"] = _RENAMED_UNITS[unit]
        for v in node.values():
            _current_units(v)
    elif isinstance(node, list):
        for v in node:
            _current_units(v)


_PLACEHOLDERS = ("oneOf", "anyOf", "allOf", "enum")
_Node = TypeVar("_Node")


def clean_td(node: _Node, *, in_forms: bool = False) -> _Node:
    """Drop empty placeholder keywords (``"oneOf": []``...) that wotpy writes into data schemas.

    They are invalid JSON Schema and make node-wot reject property values; an
    empty ``additionalResponses`` in a form says nothing either. Works in place
    and returns the document.
    """
    if isinstance(node, dict):
        for k in [k for k, v in node.items()
                  if v == [] and (k in _PLACEHOLDERS or (in_forms and k == "additionalResponses"))]:
            del node[k]
        for k, v in node.items():
            clean_td(v, in_forms=in_forms or k == "forms")
    elif isinstance(node, list):
        for v in node:
            clean_td(v, in_forms=in_forms)
    return node
