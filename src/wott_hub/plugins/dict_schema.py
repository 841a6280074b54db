"""Families whose settings are a JSON Schema dict, not a ``SettingsModel``: what the registry adds.

A plugin written before settings models hands ``FamilyInfo`` a JSON Schema dict;
the registry still accepts it (a plugin is never broken by the hub's own move to
models) and checks a device's settings against it with jsonschema, as it checks
every family's. A dict declares no Python types, so two things a model does by
itself are done here, after that check: ``with_defaults`` fills in the defaults
of the properties not given, and refuses NaN and infinities anywhere in the
settings and any ``number`` beyond ``DEFAULT_NUMBER_LIMIT`` whose property
declares no maximum of its own (JSON Schema's ``maximum`` lets NaN through:
every comparison with it is false). Errors are ``SettingsError``s naming the
setting only (``wott_hub.plugins.naming_device`` adds the device).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping
from typing import Any

from wott_hub.errors import SettingsError

__all__ = ["DEFAULT_NUMBER_LIMIT", "with_defaults"]

DEFAULT_NUMBER_LIMIT = 1e9
"""Largest magnitude of a ``number`` setting whose schema declares no ``maximum`` of its own."""


def with_defaults(schema: Mapping[str, Any], given: Mapping[str, Any] | None) -> dict[str, Any]:
    """``given`` plus (deep copies of) the defaults of the schema's properties it lacks, once its
    numbers are checked; the rest is the schema's (jsonschema's) job."""
    out = dict(given or {})
    _check_numbers(schema, out, "")
    for key, prop in (schema.get("properties") or {}).items():
        if key not in out and isinstance(prop, Mapping) and "default" in prop:
            out[key] = copy.deepcopy(prop["default"])
    return out


def _check_numbers(schema: Mapping[str, Any], settings: Mapping[str, Any], where: str) -> None:
    props = schema.get("properties") or {}
    for key, value in settings.items():
        _check_number(value, props.get(key) if isinstance(props, Mapping) else None, f"{where}{key}")


def _check_number(value: Any, prop: Any, name: str) -> None:
    if isinstance(value, float):
        if not math.isfinite(value):
            raise SettingsError(f"setting {name!r}: a finite number, got {value!r}")
        declared = isinstance(prop, Mapping) and ("maximum" in prop or "exclusiveMaximum" in prop)
        if not declared and abs(value) > DEFAULT_NUMBER_LIMIT:
            raise SettingsError(f"setting {name!r}: got {value!r}; must be at most {DEFAULT_NUMBER_LIMIT:g} "
                                "in magnitude")
    elif isinstance(value, Mapping):
        _check_numbers(prop if isinstance(prop, Mapping) else {}, value, f"{name}.")
    elif isinstance(value, list | tuple):
        items = prop.get("items") if isinstance(prop, Mapping) else None
        for i, v in enumerate(value):
            _check_number(v, items, f"{name}[{i}]")
