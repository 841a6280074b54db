"""The hub's URL layout and the forms it writes into every TD.

One HTTP port serves, under ``/wot``:

- ``GET /wot``: the catalogue ``{id: "/wot/<id>"}`` (``?expanded=1``: the TDs)
- ``GET /wot/<id>``: the TD (``application/td+json``)
- ``GET /wot/<id>/properties``: all property values; ``.../properties/<name>``: one
- ``GET /wot/<id>/properties/<name>/observe``: SSE stream of an observable property
- ``GET /wot/<id>/events/<name>``: SSE stream of one event; ``.../events``: of all events
- ``POST /wot/<id>/actions/<name>``: invoke an action (JSON input and output)
- ``GET /contexts/tactile-v1.jsonld``: the Tactile JSON-LD context

``/things`` is left to the TD directory (the W3C Discovery API owns that path).
The WebSocket port serves wotpy's JSON-RPC at ``ws://host:port/<id>``.

Every form states ``op`` and ``contentType``; HTTP forms state ``htv:methodName``
and SSE forms ``subprotocol: "sse"`` (node-wot picks forms by these). An SSE
form's ``contentType`` is that of each message's data, ``application/json``:
node-wot decodes notifications by it (``text/event-stream`` is the transport,
which ``subprotocol`` already says). Its ``op`` lists the matching unsubscribe
operation, closing the stream, so that node-wot stops over the same form. Hrefs are
absolute because wotpy's HTTP client fetches ``form.href`` without resolving it
against ``base``. HTTP forms come first: wotpy reads properties over HTTP and
takes the first HTTP form.

It lives with the TD builder (pure, no wotpy) so that a TD printed by ``wott-hub td
show`` has the same forms as the one the hub serves.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any
from urllib.parse import quote

from slugify import slugify

from wott_hub.types import FormFactory

from .mqtt import MqttLayout

__all__ = ["CONTEXT_PATH", "PREFIX", "FormLayout"]

CONTEXT_PATH = "contexts/tactile-v1.jsonld"

PREFIX = "/wot"
JSON = "application/json"


@dataclass(frozen=True)
class FormLayout:
    """Where a Thing's affordances are served: ``http_base`` like ``http://127.0.0.1:8080``."""

    http_base: str
    ws_base: str | None = None
    mqtt: MqttLayout | None = None  # [mqtt]: every event and observable property on the broker too

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
        mqtt = self.mqtt

        def forms(kind: str, name: str, affordance: dict[str, Any]) -> list[dict[str, Any]]:
            out = _forms(kind, name, affordance)
            if mqtt is not None:  # after HTTP and WebSocket: clients that know only those are unchanged
                out += mqtt.forms(thing, kind, name, affordance)
            return out

        def _forms(kind: str, name: str, affordance: dict[str, Any]) -> list[dict[str, Any]]:
            if kind == "property":
                href = f"{base}/properties/{quote(name, safe='')}"
                out = [{"href": href, "op": ["readproperty"], "htv:methodName": "GET",
                        "contentType": JSON}]
                if affordance.get("observable"):
                    out.append({"href": f"{href}/observe", "op": ["observeproperty", "unobserveproperty"],
                                "htv:methodName": "GET", "subprotocol": "sse", "contentType": JSON})
                if ws:
                    ops = ["readproperty"]
                    if affordance.get("observable"):
                        ops += ["observeproperty", "unobserveproperty"]
                    out.append({"href": ws, "op": ops, "contentType": JSON})
                return out
            if kind == "action":  # invoked over HTTP only (wott_hub.hub.device_actions serves it)
                return [{"href": f"{base}/actions/{quote(name, safe='')}", "op": ["invokeaction"],
                         "htv:methodName": "POST", "contentType": JSON}]
            out = [{"href": f"{base}/events/{quote(name, safe='')}",
                    "op": ["subscribeevent", "unsubscribeevent"],
                    "htv:methodName": "GET", "subprotocol": "sse", "contentType": JSON}]
            if ws:
                out.append({"href": ws, "op": ["subscribeevent", "unsubscribeevent"], "contentType": JSON})
            return out

        return forms

    def thing_forms(self, thing: str) -> list[dict[str, Any]]:
        base = self.thing_url(thing)
        return [
            {"href": f"{base}/properties", "op": ["readallproperties"], "htv:methodName": "GET",
             "contentType": JSON},
            {"href": f"{base}/events", "op": ["subscribeallevents", "unsubscribeallevents"],
             "htv:methodName": "GET", "subprotocol": "sse", "contentType": JSON},
        ]
