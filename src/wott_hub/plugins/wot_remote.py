"""The built-in family ``wot-remote``: adopt a tactile device that already speaks WoT.

Discovery hands every foreign TD to ``Registry.claim``; this family claims the
ones that carry the Tactile affordances the hub needs (``skinNodes``,
``skinCells`` readable over HTTP, ``skinDeformedDetection`` over SSE) and
re-exposes them with the hub's own Tactile TD through
``wott_hub.drivers.remote.RemoteWoTDriver``. A device can also be configured
by hand with the URL of its TD.

A Thing that is itself a re-exposure (``tac:family`` ``wot-remote``) is left
alone: the original is adopted instead, and two hubs can never re-expose each
other's copies forever. Third-party plugins are asked before this family
(pluggy calls later registrations first), so one that knows a device better
wins it.
"""

from __future__ import annotations

from typing import Any

from slugify import slugify

from wott_hub.drivers.remote import FAMILY, tactile_affordances

from .model import DeviceConfig, FamilyInfo

__all__ = ["FAMILY", "SCHEMA", "claim_td", "family", "open_device"]

SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "type": "object",
    "properties": {
        "url": {"type": "string", "description": "URL of the device's Thing Description (http or https)."},
        "td": {"type": "object", "description": "The device's TD itself (what discovery passes)."},
        "title": {"type": "string", "description": "Title of the re-exposed device (default: the TD's)."},
        "timeout_s": {"type": "number", "exclusiveMinimum": 0, "default": 5.0,
                      "description": "Connect and property-read timeout, seconds."},
        "idle_timeout_s": {"type": "number", "exclusiveMinimum": 0, "default": 60.0,
                           "description": "Reconnect (resuming) after this long without a byte on the "
                                          "event stream; a wott-hub sends a heartbeat every 15 s."},
        "epsilon_mm": {"type": "number", "exclusiveMinimum": 0,
                       "description": "Deformation threshold ε; default: the TD's tac:epsilon less one "
                                      "rounding step of the packets."},
        "thickness_mm": {"type": "number", "exclusiveMinimum": 0, "default": 3.0,
                         "description": "Skin thickness for the force model (not in a Tactile TD)."},
    },
    "additionalProperties": False,
    "oneOf": [{"required": ["url"]}, {"required": ["td"]}],
}


def family() -> FamilyInfo:
    return FamilyInfo(FAMILY, "A tactile device that speaks WoT itself (Tactile TD over HTTP + SSE), "
                              "found by discovery or given by the URL of its TD.", SCHEMA)


def claim_td(td: dict[str, Any]) -> DeviceConfig | None:
    if td.get("tac:family") == FAMILY:
        return None  # a re-exposure: adopt the original, not a copy
    if tactile_affordances(td) is None:
        return None
    name = td.get("title") if isinstance(td.get("title"), str) else None
    device_id = slugify(name or str(td.get("id") or ""), max_length=60) or "wot-device"
    return DeviceConfig(device_id, FAMILY, {"td": td})


def open_device(config: DeviceConfig):
    from wott_hub.drivers.remote import RemoteWoTDriver

    s = config.settings
    return RemoteWoTDriver(config.id, td=s.get("td"), url=s.get("url"), title=s.get("title"),
                           timeout_s=float(s["timeout_s"]), idle_timeout_s=float(s["idle_timeout_s"]),
                           epsilon_mm=s.get("epsilon_mm"), thickness_mm=float(s["thickness_mm"]))
