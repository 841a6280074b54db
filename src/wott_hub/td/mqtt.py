"""MQTT topics, QoS and TD forms of the hub's MQTT event path (W3C WoT MQTT binding template).

One topic per affordance, under the hub's prefix (default ``wott/<hub-id>``)::

    <prefix>/<thing>/events/<name>       every event                 (not retained)
    <prefix>/<thing>/properties/<name>   each observable property change (retained: the last value)
    <prefix>/<thing>/td                  the Thing's TD              (retained, QoS 1; empty when it goes)
    <prefix>/<thing>/binary/events/<name>  an event's binary form (``skinDisplacement``: the packet
                                         layout of docs/tactile-td.md), beside its JSON topic; not
                                         under ``events/``, so ``wott/+/+/events/#`` stays JSON only

``<thing>`` is the short name of the hub's URL paths (``barrel-1``, ``hub``), so a
fleet is one subscription: ``wott/+/+/events/#``.

QoS, chosen for what each message is worth against what it costs:

- ``skinDeformedDetection`` and ``skinDisplacement`` (one per frame, 30-1000 Hz per device): ``event_qos``,
  0 by default. A lost one is superseded by the next frame a few ms later, the
  hub's history and SSE resume hold every one, and QoS 1 doubles the packets and
  makes the broker keep per-subscriber state for a stream nobody re-reads.
- ``contactInformation`` (changes every frame while touched): ``event_qos`` too, for
  the same reasons, and retained, so a consumer arriving later gets the current
  value at once. At QoS 1 it cost the hub ~75 us of CPU per change (paho's
  acknowledgement handling), a third of a core at 32 devices x 120 Hz.
- every other event (``actionDetection``, the hub's ``healthChange``): QoS 1, a
  few per second at most, each one matters (a press, a device failing).
- every other property change (rare: ``health``, ``unavailableNodes``,
  ``skinNodes``) and TDs: QoS 1, retained.

Forms follow the binding template's vocabulary (context ``mqv``): ``href`` is the
broker with the topic as its path, ``mqv:filter`` the topic to subscribe to,
``mqv:controlPacket`` ``subscribe``, ``mqv:qos`` as a string ("0"/"1"/"2"),
``mqv:retain`` for retained topics. The hub only publishes: there are no
``writeproperty``/``invokeaction`` MQTT forms.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from wott_hub.events.fields import CONTENT_TYPE as DISPLACEMENT_BINARY
from wott_hub.events.fields import SKIN_DISPLACEMENT

__all__ = ["BINARY_EVENTS", "HIGH_RATE_EVENTS", "HIGH_RATE_PROPERTIES", "MQV_CONTEXT", "MqttLayout"]

MQV_CONTEXT = {"mqv": "https://www.w3.org/2019/wot/mqtt#"}
"""The prefix the binding template's context defines for its terms."""

HIGH_RATE_EVENTS = frozenset({"skinDeformedDetection", SKIN_DISPLACEMENT})
BINARY_EVENTS = {SKIN_DISPLACEMENT: DISPLACEMENT_BINARY}
"""Events also published in a binary form (on ``binary_topic``): name -> its contentType."""
HIGH_RATE_PROPERTIES = frozenset({"contactInformation"})
JSON = "application/json"


@dataclass(frozen=True)
class MqttLayout:
    """Where a hub's records go on the broker: ``broker`` like ``mqtt://127.0.0.1:1883``."""

    broker: str
    prefix: str
    event_qos: int = 0

    def event_topic(self, thing: str, name: str) -> str:
        return f"{self.prefix}/{thing}/events/{name}"

    def property_topic(self, thing: str, name: str) -> str:
        return f"{self.prefix}/{thing}/properties/{name}"

    def binary_topic(self, thing: str, name: str) -> str:
        return f"{self.prefix}/{thing}/binary/events/{name}"

    def td_topic(self, thing: str) -> str:
        return f"{self.prefix}/{thing}/td"

    def qos(self, kind: str, name: str) -> int:
        """``kind``: 'event' or 'property'."""
        if name in (HIGH_RATE_EVENTS if kind == "event" else HIGH_RATE_PROPERTIES):
            return self.event_qos
        return 1

    @staticmethod
    def retain(kind: str) -> bool:
        return kind == "property"

    def forms(self, thing: str, kind: str, name: str, affordance: dict[str, Any]) -> list[dict[str, Any]]:
        """The MQTT forms of an event or an observable property (none for other properties)."""
        if kind == "event":
            topic, ops = self.event_topic(thing, name), ["subscribeevent", "unsubscribeevent"]
        elif affordance.get("observable"):
            topic, ops = self.property_topic(thing, name), ["observeproperty", "unobserveproperty"]
        else:
            return []
        form: dict[str, Any] = {"href": f"{self.broker}/{topic}", "op": ops, "contentType": JSON,
                                "mqv:controlPacket": "subscribe", "mqv:filter": topic,
                                "mqv:qos": str(self.qos(kind, name))}
        if self.retain(kind):
            form["mqv:retain"] = True
        if kind == "event" and name in BINARY_EVENTS:
            binary = self.binary_topic(thing, name)
            return [form, {**form, "href": f"{self.broker}/{binary}", "mqv:filter": binary,
                           "contentType": BINARY_EVENTS[name]}]
        return [form]

    @staticmethod
    def add_context(td: dict[str, Any]) -> None:
        """Declare the ``mqv`` prefix in the TD's ``@context`` (once)."""
        ctx = td.get("@context")
        if not isinstance(ctx, list):
            ctx = [ctx] if ctx else []
        if MQV_CONTEXT not in ctx:
            ctx.append(dict(MQV_CONTEXT))
        td["@context"] = ctx
