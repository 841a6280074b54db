"""The hub's URL layout, the forms it writes into every TD, and the TD clean-up.

One HTTP port serves, under ``/wot``:

- ``GET /wot``: the catalogue ``{id: "/wot/<id>"}`` (``?expanded=1``: the TDs)
- ``GET /wot/<id>``: the TD (``application/td+json``)
- ``GET /wot/<id>/properties``: all property values; ``.../properties/<name>``: one
- ``GET /wot/<id>/properties/<name>/observe``: SSE stream of an observable property
- ``GET /wot/<id>/events/<name>``: SSE stream of one event; ``.../events``: of all events

``/things`` is left to the TD directory (the W3C Discovery API owns that path).
The WebSocket port serves wotpy's JSON-RPC at ``ws://host:port/<id>``.

Every form states ``op`` and ``contentType``; HTTP forms state ``htv:methodName``
and SSE forms ``subprotocol: "sse"`` (node-wot picks forms by these). Hrefs are
absolute because wotpy's HTTP client fetches ``form.href`` without resolving it
against ``base``. HTTP forms come first: wotpy reads properties over HTTP and
takes the first HTTP form.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any
from urllib.parse import quote

from slugify import slugify

from wott_hub.td.builder import CONTEXT_PATH, FormFactory

__all__ = ["PREFIX", "FormLayout", "clean_td", "with_forms"]

PREFIX = "/wot"
SSE = "text/event-stream"
JSON = "application/json"


@dataclass(frozen=True)
class FormLayout:
    """Where a Thing's affordances are served: ``http_base`` like ``http://127.0.0.1:8080``."""

    http_base: str
    ws_base: str | None = None

    @property
    def context_url(self) -> str:
        return f"{self.http_base}/{CONTEXT_PATH}"

    def thing_url(self, thing: str) -> str:
        return f"{self.http_base}{PREFIX}/{quote(thing, safe='')}"

    def ws_url(self, thing: str) -> str | None:
        # wotpy's WebSocket server routes by the URL-safe form of the Thing's wotpy title (its id)
        return f"{self.ws_base}/{slugify(thing)}" if self.ws_base else None

    def factory(self, thing: str) -> FormFactory:
        base = self.thing_url(thing)
        ws = self.ws_url(thing)

        def forms(kind: str, name: str, affordance: dict[str, Any]) -> list[dict[str, Any]]:
            if kind == "property":
                href = f"{base}/properties/{quote(name, safe='')}"
                out = [{"href": href, "op": ["readproperty"], "htv:methodName": "GET",
                        "contentType": JSON}]
                if affordance.get("observable"):
                    out.append({"href": f"{href}/observe", "op": ["observeproperty"],
                                "htv:methodName": "GET", "subprotocol": "sse", "contentType": SSE})
                if ws:
                    ops = ["readproperty"]
                    if affordance.get("observable"):
                        ops += ["observeproperty", "unobserveproperty"]
                    out.append({"href": ws, "op": ops, "contentType": JSON})
                return out
            out = [{"href": f"{base}/events/{quote(name, safe='')}", "op": ["subscribeevent"],
                    "htv:methodName": "GET", "subprotocol": "sse", "contentType": SSE}]
            if ws:
                out.append({"href": ws, "op": ["subscribeevent", "unsubscribeevent"], "contentType": JSON})
            return out

        return forms

    def thing_forms(self, thing: str) -> list[dict[str, Any]]:
        base = self.thing_url(thing)
        return [
            {"href": f"{base}/properties", "op": ["readallproperties"], "htv:methodName": "GET",
             "contentType": JSON},
            {"href": f"{base}/events", "op": ["subscribeallevents"], "htv:methodName": "GET",
             "subprotocol": "sse", "contentType": SSE},
        ]


def with_forms(td: dict[str, Any], thing: str, layout: FormLayout) -> dict[str, Any]:
    """A copy of ``td`` whose forms and ``base`` are this hub's (e.g. a recorded TD, re-served)."""
    out = copy.deepcopy(td)
    factory = layout.factory(thing)
    for kind, key in (("property", "properties"), ("event", "events")):
        for name, aff in (out.get(key) or {}).items():
            aff["forms"] = factory(kind, name, aff)
    out["forms"] = layout.thing_forms(thing)
    out["base"] = f"{layout.http_base}/"
    return clean_td(out)


_PLACEHOLDERS = ("oneOf", "anyOf", "allOf", "enum")


def clean_td(node: Any, *, in_forms: bool = False) -> Any:
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
