"""Reading device settings against a family's JSON-Schema-ish settings schema, for plugins.

Not tied to any family: ``with_defaults`` is what the registry fills in before a
plugin sees a device's settings; ``defaults`` also refuses keys the schema does
not list (for nested tables, which get their defaults only from the family, and
for families opened directly, without the registry); ``BACKOFF_PROPERTIES`` and
``backoff`` are the reconnect-pacing settings a family with a transport that
comes and goes splices into its schema and reads. Errors are ``DriverError``s
naming the setting only (``wott_hub.plugins.naming_device`` adds the device).
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any

from wott_hub.drivers.backoff import Backoff
from wott_hub.drivers.base import DriverError

__all__ = ["BACKOFF_PROPERTIES", "backoff", "defaults", "with_defaults"]

BACKOFF_PROPERTIES: dict[str, Any] = {
    "backoff_initial_s": {"type": "number", "default": 0.05, "description": "First reconnect delay, s.",
                          "exclusiveMinimum": 0},
    "backoff_cap_s": {"type": "number", "default": 5.0, "description": "Longest reconnect delay, s.",
                      "exclusiveMinimum": 0},
}


def with_defaults(schema: Mapping[str, Any], given: Mapping[str, Any] | None) -> dict[str, Any]:
    """``given`` plus (deep copies of) the defaults of the schema's properties it lacks; nothing checked."""
    out = dict(given or {})
    for key, prop in (schema.get("properties") or {}).items():
        if key not in out and isinstance(prop, Mapping) and "default" in prop:
            out[key] = copy.deepcopy(prop["default"])
    return out


def defaults(schema: Mapping[str, Any], given: Mapping[str, Any] | None, where: str = "") -> dict[str, Any]:
    """``given`` completed with the schema's defaults; a key the schema does not list is an error
    naming it (prefixed with ``where``, e.g. ``"render."``).

    The registry checks the top level against the schema before a plugin sees it, but a family
    can be opened directly (tests, scripts), and nested tables get their defaults only here.
    """
    given = dict(given or {})
    unknown = sorted(set(given) - set(schema["properties"]))
    if unknown:
        raise DriverError(f"unknown setting(s) {', '.join(where + u for u in unknown)}")
    out = with_defaults(schema, None)  # the schema's order, then what is given without a default
    out.update(given)
    return out


def backoff(s: Mapping[str, Any]) -> Backoff:
    """The ``Backoff`` of the settings ``backoff_initial_s`` and ``backoff_cap_s`` (BACKOFF_PROPERTIES)."""
    try:
        return Backoff(initial_s=float(s["backoff_initial_s"]), cap_s=float(s["backoff_cap_s"]))
    except ValueError as e:
        raise DriverError(f"backoff_initial_s/backoff_cap_s: {e}") from None
