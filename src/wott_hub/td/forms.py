"""The hub's URL layout and the forms it writes into every TD.

One HTTP port serves, under ``/wot``:

- ``GET /wot``: the catalogue ``{id: "/wot/<id>"}`` (``?expanded=1``: the TDs)
- ``GET /wot/<id>``: the TD (``application/td+json``)
- ``GET /wot/<id>/properties``: all property values; ``.../properties/<name>``: one
- ``GET /wot/<id>/properties/<name>/observe``: SSE stream of an observable property
- ``GET /wot/<id>/events/<name>``: SSE stream of one event; ``.../events``: of all events
- ``GET /wot/<id>/events/skinDisplacement/binary``: its binary packets, one HTTP response that never
  ends (``subprotocol: "stream"``); ``.../binary/ws``: the same as WebSocket binary messages
- ``GET /wot/<id>/properties/rawImage``, ``pressureGrid`` (devices with raw signals): JSON, or
  ``?format=png|jpeg|npy``; ``.../stream``: a ``multipart/x-mixed-replace`` JPEG stream, an SSE
  stream of grids (``td.raw``)
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

from wott_hub.events.fields import CONTENT_TYPE as DISPLACEMENT_BINARY
from wott_hub.events.fields import SKIN_DISPLACEMENT
from wott_hub.types import FormFactory

from .mqtt import MqttLayout
from .raw import RAW_IMAGE, RAW_PROPERTIES, RAW_TYPES

__all__ = ["BINARY_EVENTS", "CONTEXT_PATH", "NPY", "PREFIX", "STREAM", "FormLayout"]

CONTEXT_PATH = "contexts/tactile-v1.jsonld"

PREFIX = "/wot"
JSON = "application/json"
NPY = "application/x-npy"
"""NumPy's .npy file (its header then the array), the media type NumPy-serving tools use."""
STREAM = "stream"
"""The subprotocol of an HTTP form whose one GET response never ends: messages follow one another, framed
as its contentType says (self-delimiting packets, multipart parts). SSE forms say ``sse``."""
MULTIPART = "multipart/x-mixed-replace;boundary=frame"
BINARY_EVENTS = {SKIN_DISPLACEMENT: DISPLACEMENT_BINARY}
"""Events with a binary form: name -> its contentType."""


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
            if kind == "property" and affordance.get("@type") in RAW_TYPES:
                return _raw_forms(f"{base}/properties/{quote(name, safe='')}", name)
            out = _forms(kind, name, affordance)
            if kind == "event" and name in BINARY_EVENTS:
                href = f"{base}/events/{quote(name, safe='')}/binary"
                ops = ["subscribeevent", "unsubscribeevent"]
                out.append({"href": href, "op": ops, "htv:methodName": "GET", "subprotocol": STREAM,
                            "contentType": BINARY_EVENTS[name]})
                ws_href = href.replace("http", "ws", 1) + "/ws"
                out.append({"href": ws_href, "op": ops, "contentType": BINARY_EVENTS[name]})
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

    def raw_paths(self, thing: str) -> dict[str, str]:
        """Where a device's raw-signal properties are read (for the twin and tests)."""
        base = self.thing_url(thing)
        return {name: f"{base}/properties/{name}" for name in sorted(RAW_PROPERTIES)}

    def thing_forms(self, thing: str) -> list[dict[str, Any]]:
        base = self.thing_url(thing)
        return [
            {"href": f"{base}/properties", "op": ["readallproperties"], "htv:methodName": "GET",
             "contentType": JSON},
            {"href": f"{base}/events", "op": ["subscribeallevents", "unsubscribeallevents"],
             "htv:methodName": "GET", "subprotocol": "sse", "contentType": JSON},
        ]


def _raw_forms(href: str, name: str) -> list[dict[str, Any]]:
    """A raw signal's forms: JSON first and with a plain href (wotpy reads a property through its first HTTP
    form, as it is, and decodes JSON), then the binary media types, then the observe form every observable
    property has (plain href, SSE or long-poll of JSON: wotpy 0.18 observes through the first observe form,
    requesting its href as it is: a templated ``{?maxRate}`` first was a 404, issue 48), then the stream."""
    read = {"op": ["readproperty"], "htv:methodName": "GET"}
    ops = ["observeproperty", "unobserveproperty"]
    plain = {"href": f"{href}/observe", "op": ops, "htv:methodName": "GET", "subprotocol": "sse",
             "contentType": JSON}
    observe = {"op": ops, "htv:methodName": "GET", "subprotocol": STREAM}
    if name == RAW_IMAGE:
        return [{"href": href, **read, "contentType": JSON},
                {"href": f"{href}?format=png{{&camera}}", **read, "contentType": "image/png"},
                {"href": f"{href}?format=jpeg{{&camera}}", **read, "contentType": "image/jpeg"},
                {"href": f"{href}?format=npy{{&camera}}", **read, "contentType": NPY}, plain,
                {"href": f"{href}/stream{{?camera,maxRate}}", **observe, "contentType": MULTIPART}]
    return [{"href": href, **read, "contentType": JSON},
            {"href": f"{href}?format=npy{{&signal}}", **read, "contentType": NPY}, plain,
            {"href": f"{href}/stream{{?signal,maxRate}}", **observe, "subprotocol": "sse",
             "contentType": JSON}]
