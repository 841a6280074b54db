"""The hub's own Thing: which devices it serves, their health, event counters.

It is a plain TD 1.1 Thing (not a Tactile one), served like the devices: a WoT
client can read ``devices`` to find every device TD, observe ``health`` and
subscribe to ``healthChange``.
"""

from __future__ import annotations

from typing import Any

from wott_hub.td.vocabulary import TD_CONTEXT

from .forms import FormLayout, with_forms

__all__ = ["HUB_THING_ID", "hub_td"]

HUB_THING_ID = "hub"

_STATE = {"type": "string", "enum": ["ok", "degraded", "disconnected", "starting", "ended", "failed"]}


def hub_td(name: str, layout: FormLayout) -> dict[str, Any]:
    td = {
        "@context": list(TD_CONTEXT),
        "id": f"urn:wott-hub:hub:{name}",
        "title": name,
        "description": "A wott-hub gateway: the tactile devices it serves, their health and event counters.",
        "securityDefinitions": {"nosec_sc": {"scheme": "nosec"}},
        "security": "nosec_sc",
        "properties": {
            "devices": {
                "title": "devices",
                "description": "Every device of the hub, with the URL of its TD.",
                "type": "array",
                "readOnly": True,
                "items": {
                    "type": "object",
                    "properties": {
                        "id": {"type": "string"},
                        "title": {"type": "string"},
                        "family": {"type": "string"},
                        "td": {"type": "string", "format": "uri"},
                        "state": _STATE,
                        "recorded": {"type": "boolean"},
                    },
                    "required": ["id", "td", "state"],
                },
            },
            "health": {
                "title": "health",
                "description": "The hub's state and each device's (state, reason, since).",
                "type": "object",
                "readOnly": True,
                "observable": True,
                "properties": {
                    "state": _STATE,
                    "uptimeSeconds": {"type": "number", "unit": "s"},
                    "devices": {"type": "object"},
                    "history": {"type": "object"},
                    "mqtt": {"type": "object",
                             "description": "With [mqtt]: the broker link (state, counters)."},
                },
                "required": ["state", "devices"],
            },
            "eventCounters": {
                "title": "eventCounters",
                "description": "Per Thing: records published (by affordance), last seq, subscribers; "
                               "history: written, queued, dropped.",
                "type": "object",
                "readOnly": True,
                "properties": {
                    "things": {"type": "object"},
                    "history": {"type": "object"},
                    "overflowDisconnects": {"type": "integer", "minimum": 0},
                },
            },
        },
        "events": {
            "healthChange": {
                "title": "healthChange",
                "description": "A device changed state (ok, degraded, disconnected, ended, failed).",
                "data": {
                    "type": "object",
                    "properties": {
                        "device": {"type": "string"},
                        "state": _STATE,
                        "reason": {"type": "string"},
                        "timeStamp": {"type": "integer", "description": "ns since the epoch"},
                    },
                    "required": ["device", "state"],
                },
            },
        },
    }
    return with_forms(td, HUB_THING_ID, layout)
