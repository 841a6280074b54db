"""The actions a Tactile device declares, and the ``deviceAction`` event that records each invocation.

Every device TD declares ``restart``; ``tare`` and ``recalibrate`` only where the
device's driver has that capability (``wott_hub.drivers.base.Tareable`` /
``Recalibratable``), so a TD never promises what its device cannot do. Each
invocation, whatever its outcome, is published as a ``deviceAction`` event on the
device's own stream: subscribers see it in order with the frames it affects, and
history keeps it with the device's records. Every data schema states its ``type``
(wotpy cannot consume one without; node-wot validates outputs against it).

Pure data: the hub (``wott_hub.hub.device_actions``) serves and performs them.
"""

from __future__ import annotations

import copy
from typing import Any

__all__ = ["ALWAYS", "DEVICE_ACTIONS", "DEVICE_ACTION_EVENT", "declared_actions"]

_OUTCOME = {
    "type": "object",
    "properties": {
        "device": {"type": "string", "description": "The device's Thing id."},
        "invokedAction": {"type": "string", "description": "The action performed."},
        "outcome": {"type": "string", "enum": ["ok", "failed"],
                    "description": "ok: done (or, for tare, the next frame becomes the rest reference)."},
        "detail": {"type": "string", "description": "What was done, or why it failed."},
        "timeStamp": {"type": "integer", "description": "When it was invoked, ns since the epoch."},
    },
}

DEVICE_ACTIONS: dict[str, dict[str, Any]] = {
    "tare": {
        "title": "tare",
        "description": "Take a new rest reference now: the next frame is the skin at rest (vision pads and "
                       "barrel: a new marker reference; taxel arrays: zero offsets).",
        "safe": False,
        "idempotent": False,
        "synchronous": True,
        "input": {"type": "object", "properties": {}},
        "output": _OUTCOME,
    },
    "restart": {
        "title": "restart",
        "description": "Close the device's driver and open it again from its configuration. The Thing, "
                       "its streams and its sequence numbers are kept: subscribers stay connected.",
        "safe": False,
        "idempotent": False,
        "synchronous": True,
        "input": {"type": "object", "properties": {}},
        "output": _OUTCOME,
    },
    "recalibrate": {
        "title": "recalibrate",
        "description": "Redo the device's calibration from what it sees now (vision pads and barrel: "
                       "re-detect the marker grid and restart tracking from it); the skin must be at rest.",
        "safe": False,
        "idempotent": False,
        "synchronous": True,
        "input": {"type": "object", "properties": {}},
        "output": _OUTCOME,
    },
}

ALWAYS = ("restart",)
"""Declared by every device: the hub does it, whatever the driver."""

DEVICE_ACTION_EVENT: dict[str, dict[str, Any]] = {
    "deviceAction": {
        "title": "deviceAction",
        "@type": "tac:DeviceAction",
        "description": "One invocation of a device action (tare, restart, recalibrate) and its outcome.",
        "data": _OUTCOME,
    },
}


def declared_actions(names: tuple[str, ...] | list[str] = ("tare", "restart")) -> dict[str, dict[str, Any]]:
    """Copies of the affordances named (without forms), in ``DEVICE_ACTIONS`` order."""
    return {n: copy.deepcopy(a) for n, a in DEVICE_ACTIONS.items() if n in names}
