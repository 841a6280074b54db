"""Reading a device family's settings, declared as a model or (older plugins) a JSON Schema dict.

Not tied to any family: ``with_defaults`` is what the registry fills in before a
plugin sees a device's settings; ``defaults`` also refuses keys the schema does
not list (for nested tables, which get their defaults only from the family, and
for families opened directly, without the registry); ``BACKOFF_PROPERTIES`` and
``backoff`` are the reconnect-pacing settings a family with a transport that
comes and goes splices into its schema and reads. Errors are ``DriverError``s
naming the setting only (``wott_hub.plugins.naming_device`` adds the device).

Bounds (issue 16): JSON Schema's ``maximum`` lets NaN through (every comparison
with NaN is false), so ``with_defaults``, which the registry runs on every
device's settings after the schema check, refuses NaN and infinities anywhere
in the settings, and any ``number`` property whose schema declares no upper
bound is held to ``|x| <= DEFAULT_NUMBER_LIMIT``.

The declared way, which every first-party family uses: a msgspec model
(``SettingsModel``: typed fields with ``Meta(ge=..., le=...)`` bounds, nested
tables as frozen models): ``settings_schema`` gives the JSON Schema its
``FamilyInfo`` carries (docs, ``wott-hub plugins families``; nested tables
inlined, an optional ``T | None = None`` shown as ``T``) and ``read_settings``
the checked, typed settings, with the same one-line errors as the hub's own
config (``wott_hub.configspec``). The dict functions above (``with_defaults``,
``defaults``, ``BACKOFF_PROPERTIES``) stay as the documented path for
third-party plugins that hand the registry a JSON Schema dict.
"""

from __future__ import annotations

import copy
import math
import re
from collections.abc import Mapping
from typing import Annotated, Any, ClassVar, TypeVar

import msgspec
from msgspec import Meta

from wott_hub.configspec import ConfigError, Model, json_schema, read
from wott_hub.drivers.backoff import Backoff
from wott_hub.errors import DriverError

__all__ = ["BACKOFF_PROPERTIES", "DEFAULT_NUMBER_LIMIT", "BackoffSettings", "Meta", "SettingsModel",
           "SettingsTable", "backoff", "check_numbers", "defaults", "model_fields", "model_settings",
           "read_settings", "settings_schema", "with_defaults"]

DEFAULT_NUMBER_LIMIT = 1e9
"""Largest magnitude of a ``number`` setting whose schema declares no ``maximum`` of its own."""

BACKOFF_PROPERTIES: dict[str, Any] = {
    "backoff_initial_s": {"type": "number", "default": 0.05, "description": "First reconnect delay, s.",
                          "exclusiveMinimum": 0, "maximum": 60},
    "backoff_cap_s": {"type": "number", "default": 5.0, "description": "Longest reconnect delay, s.",
                      "exclusiveMinimum": 0, "maximum": 3600},
}

class SettingsModel(Model):
    """Base of a family's settings declared as a model: a msgspec ``Struct`` (keyword-only,
    unknown keys refused) whose fields carry their bounds: ``Annotated[float, Meta(gt=0, le=100)]``.

    A rule across fields that JSON Schema can say (``if``/``then``: a port unless simulated) goes
    in the class attribute ``json_schema_extra``, merged into ``settings_schema``.
    """

    json_schema_extra: ClassVar[dict[str, Any]] = {}


class SettingsTable(msgspec.Struct, kw_only=True, forbid_unknown_fields=True, frozen=True):
    """Base of a nested table of a family's settings (``[device.optics]``): frozen, so that an
    instance can be the field's default (``optics: OpticsTable = OpticsTable()``); a subclass
    says ``frozen=True`` again (type checkers do not inherit it)."""


class BackoffSettings(SettingsModel):
    """``BACKOFF_PROPERTIES`` as a model: a family with a transport that comes and goes inherits it."""

    backoff_initial_s: Annotated[float, Meta(gt=0, le=60, description="First reconnect delay, s.")] = 0.05
    backoff_cap_s: Annotated[float, Meta(gt=0, le=3600, description="Longest reconnect delay, s.")] = 5.0

M = TypeVar("M")


def settings_schema(model: type[Any]) -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of a settings model, for ``FamilyInfo``: nested tables
    inlined (no ``$ref``: the registry's messages and ``plugins families`` read one tree)."""
    schema = json_schema(model)
    defs = schema.pop("$defs", {})
    schema = _inline(schema, defs, top=True)
    schema.pop("description", None)  # the model's docstring speaks to developers, not to users
    schema.update(getattr(model, "json_schema_extra", {}))
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", **schema}


def _inline(node: Any, defs: dict[str, Any], top: bool = False) -> Any:
    if isinstance(node, list):
        return [_inline(n, defs) for n in node]
    if not isinstance(node, dict):
        return node
    if "$ref" in node:
        target = dict(defs[node["$ref"].rsplit("/", 1)[-1]])
        if not top:
            target.pop("title", None)  # the Struct's class name says nothing to a user
        rest = {k: v for k, v in node.items() if k != "$ref"}
        return _inline({**target, **rest}, defs, top)
    out = {k: v if k == "default" else _inline(v, defs) for k, v in node.items()}
    if isinstance(out.get("properties"), dict):
        out["properties"] = {k: _optional_is_absent(v) for k, v in out["properties"].items()}
    return out


def _optional_is_absent(prop: Any) -> Any:
    """``x: Annotated[T, Meta(description=...)] | None = None`` means "leave the key out" (TOML has
    no null): its property becomes ``T``'s own schema, description and all, as a hand-written
    schema says it. Where the description is on the union (``Annotated[T | None, Meta(...)]``),
    null is a value of its own and stays."""
    alts = prop.get("anyOf") if isinstance(prop, dict) else None
    if not (isinstance(alts, list) and {"type": "null"} in alts and prop.get("default", ...) is None
            and "description" not in prop):
        return prop
    rest = [a for a in alts if a != {"type": "null"}]
    extra = {k: v for k, v in prop.items() if k not in ("anyOf", "default")}
    return {**rest[0], **extra} if len(rest) == 1 else {"anyOf": rest, **extra}


def model_fields(value: Any) -> dict[str, Any]:
    """The fields of a read settings model (or of one of its nested tables) as keyword arguments,
    for the plain class a driver builds from them (``RenderSettings(**model_fields(s.render))``)."""
    return {k: getattr(value, k) for k in value.__struct_fields__}


def read_settings(model: type[M], settings: Mapping[str, Any] | None) -> M:
    """``settings`` as the model, every bound checked; a DriverError names the setting."""
    try:
        value: M = read(model, dict(settings or {}), "setting")
        return value
    except ConfigError as e:  # "setting.cameras[0].fps: ..." -> "setting 'cameras[0].fps': ..."
        m = re.match(r"^setting((?:\.[^.\[:\s]+|\[\d+\])+)(.*)$", str(e), re.S)
        raise DriverError(f"setting {m[1].lstrip('.')!r}{m[2]}" if m else str(e)) from None


def model_settings(model: type[Any], settings: Mapping[str, Any] | None) -> dict[str, Any]:
    """``settings`` checked by ``model`` and completed with its defaults, as plain values: what
    the registry hands a family declared by a model (the plugin may ``read_settings`` it again)."""
    plain: dict[str, Any] = msgspec.to_builtins(read_settings(model, settings))
    return {k: v for k, v in plain.items() if v is not None}  # unset stays absent, as in TOML


def check_numbers(schema: Mapping[str, Any], settings: Mapping[str, Any], where: str = "") -> None:
    """Refuse NaN and infinities anywhere in ``settings``, and a number beyond DEFAULT_NUMBER_LIMIT
    where the schema's property declares no maximum."""
    props = schema.get("properties") or {}
    for key, value in settings.items():
        _check_number(value, props.get(key) if isinstance(props, Mapping) else None, f"{where}{key}")


def _check_number(value: Any, prop: Any, name: str) -> None:
    if isinstance(value, float):
        if not math.isfinite(value):
            raise DriverError(f"setting {name!r}: a finite number, got {value!r}")
        declared = isinstance(prop, Mapping) and ("maximum" in prop or "exclusiveMaximum" in prop)
        if not declared and abs(value) > DEFAULT_NUMBER_LIMIT:
            raise DriverError(f"setting {name!r}: got {value!r}; must be at most {DEFAULT_NUMBER_LIMIT:g} "
                              "in magnitude")
    elif isinstance(value, Mapping):
        check_numbers(prop if isinstance(prop, Mapping) else {}, value, f"{name}.")
    elif isinstance(value, list | tuple):
        items = prop.get("items") if isinstance(prop, Mapping) else None
        for i, v in enumerate(value):
            _check_number(v, items, f"{name}[{i}]")


def with_defaults(schema: Mapping[str, Any], given: Mapping[str, Any] | None) -> dict[str, Any]:
    """``given`` plus (deep copies of) the defaults of the schema's properties it lacks; only numbers
    are checked here (``check_numbers``), the rest is the schema's job."""
    out = dict(given or {})
    check_numbers(schema, out)
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
    check_numbers(schema, given, where)
    out = with_defaults(schema, None)  # the schema's order, then what is given without a default
    out.update(given)
    return out


def backoff(s: Mapping[str, Any] | BackoffSettings) -> Backoff:
    """The ``Backoff`` of the settings ``backoff_initial_s`` and ``backoff_cap_s`` (BACKOFF_PROPERTIES,
    or a ``BackoffSettings`` model)."""
    if isinstance(s, BackoffSettings):
        s = {"backoff_initial_s": s.backoff_initial_s, "backoff_cap_s": s.backoff_cap_s}
    try:
        return Backoff(initial_s=float(s["backoff_initial_s"]), cap_s=float(s["backoff_cap_s"]))
    except ValueError as e:
        raise DriverError(f"backoff_initial_s/backoff_cap_s: {e}") from None
