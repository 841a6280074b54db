"""Reading a table against its declaration: the value, or one ``ConfigError`` naming the key."""

from __future__ import annotations

from typing import Any

import msgspec
import msgspec.json

from ._explain import explain

__all__ = ["ConfigError", "check", "json_schema", "read"]


class ConfigError(ValueError):
    """A table, key or value that is wrong; the message names where (file, table, key) and why."""


def read(model: type[Any], data: Any, where: str) -> Any:
    """``data`` (a TOML table) converted to ``model``; a wrong value raises ConfigError naming
    ``where`` (``"hub.toml: [hub]"``, ``explain`` says how it is joined to the key) and the key."""
    try:
        return msgspec.convert(data, model)
    except msgspec.ValidationError as e:
        raise ConfigError(explain(model, data, str(e), where)) from None


def check(obj: Any, model: type[Any], where: str) -> None:
    """Check the fields of a dataclass built in Python (not read from a file) against its table."""
    read(model, {n: getattr(obj, n) for n in model.__struct_fields__}, where)


def json_schema(model: type[Any]) -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of ``model``: bounds, defaults and descriptions included."""
    return msgspec.json.schema(model)
