"""A device family's settings, declared as a model and read the way the hub reads its own config.

A family declares its settings once, as a ``SettingsModel`` (a msgspec ``Struct``
through ``wott_hub.configspec``: typed fields with ``Meta(ge=..., le=...)`` bounds,
nested tables as frozen ``SettingsTable``s). That one declaration gives the JSON
Schema its ``FamilyInfo`` carries (``settings_schema``: docs, ``wott-hub plugins
families``; nested tables inlined, an optional ``T | None = None`` shown as ``T``),
the defaults, and the checked, typed settings (``read_settings``) with the same
one-line errors as the hub's own config. A wrong setting is a ``SettingsError``
naming the setting only (``setting 'cameras[0].fps': ...``);
``wott_hub.plugins.naming_device`` adds the device and family.

Every number has an upper bound (``Meta(le=...)``): NaN fails every comparison and
infinity every finite bound, so neither gets into a driver. Families that hand the
registry a JSON Schema dict instead (older third-party plugins) are checked by
``dict_schema.py``.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Annotated, Any, ClassVar, TypeVar

import msgspec
from msgspec import Meta

from wott_hub.configspec import ConfigError, Model, json_schema, read
from wott_hub.drivers.backoff import Backoff
from wott_hub.errors import SettingsError

__all__ = ["BackoffSettings", "Meta", "SettingsModel", "SettingsTable", "backoff", "model_fields",
           "model_settings", "read_settings", "settings_schema"]


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
    """The reconnect pacing of a family with a transport that comes and goes: it inherits these two."""

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
    if isinstance(model, type) and issubclass(model, SettingsModel):
        schema.update(model.json_schema_extra)
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


_SETTING = re.compile(r"^setting((?:\.[^.\[:\s]+|\[\d+\])+)(.*)$", re.S)


def read_settings(model: type[M], settings: Mapping[str, Any] | None) -> M:
    """``settings`` as the model, every bound checked; a SettingsError names the setting."""
    try:
        value: M = read(model, dict(settings or {}), "setting")
        return value
    except ConfigError as e:  # "setting.cameras[0].fps: ..." -> "setting 'cameras[0].fps': ..."
        m = _SETTING.match(str(e))
        raise SettingsError(f"setting {m[1].lstrip('.')!r}{m[2]}" if m else str(e)) from None


def model_settings(model: type[Any], settings: Mapping[str, Any] | None) -> dict[str, Any]:
    """``settings`` checked by ``model`` and completed with its defaults, as plain values: what
    the registry hands a family declared by a model (the plugin may ``read_settings`` it again)."""
    plain: dict[str, Any] = msgspec.to_builtins(read_settings(model, settings))
    return {k: v for k, v in plain.items() if v is not None}  # unset stays absent, as in TOML


def backoff(s: BackoffSettings) -> Backoff:
    """The ``Backoff`` of the settings ``backoff_initial_s`` and ``backoff_cap_s``."""
    try:
        return Backoff(initial_s=s.backoff_initial_s, cap_s=s.backoff_cap_s)
    except ValueError as e:
        raise SettingsError(f"backoff_initial_s/backoff_cap_s: {e}") from None
