"""The hub's config tables: declared with ``wott_configspec``, their errors in the hub's tree.

Every table the hub reads (``[hub]``, ``[directory]``, ``[discovery]``, ``[mqtt]``,
``[security]``, a ``[[device]]`` table, each device family's settings, a scene file) is a
msgspec ``Struct`` whose field types carry their bounds and the words a person is told
when a value is wrong: one declaration gives the check, the default, the error message
and the JSON Schema the docs show (docs/configuration.md). The machinery is
``wott_configspec``'s, shared with the Thing Description Directory so both word their
errors alike; this module is the hub's one door to it. Hub modules import these names
from here, never from ``wott_configspec``: ``read`` and ``check`` raise
``wott_hub.errors.ConfigError`` (or the subclass the caller names: ``SettingsError``,
``SceneError``) instead of the library's own error, translated here once.

Errors read ``hub.toml: [hub].workers: a whole number of processes, got 100000; must be
from 0 to 64``. This module imports msgspec, ``wott_configspec`` and ``wott_hub.errors``
only: reading a config stays cheap.
"""

from __future__ import annotations

from typing import Any

import wott_configspec
from wott_configspec import Flag, Model, bounded, doc, json_schema, says, table_of

from wott_hub.errors import ConfigError

__all__ = ["ConfigError", "Flag", "Model", "bounded", "check", "doc", "json_schema", "read", "says",
           "table_of"]


def read(model: type[Any], data: Any, where: str, error: type[ConfigError] = ConfigError) -> Any:
    """``data`` (a TOML table) converted to ``model``; a wrong value raises ``error`` naming
    ``where`` (``"hub.toml: [hub]"``; a file ends in a space: ``"scene.toml: "``) and the key."""
    try:
        return wott_configspec.read(model, data, where)
    except wott_configspec.ConfigError as e:
        raise error(str(e)) from None


def check(obj: Any, model: type[Any], where: str) -> None:
    """Check the fields of a dataclass built in Python (not read from a file) against its table."""
    try:
        wott_configspec.check(obj, model, where)
    except wott_configspec.ConfigError as e:
        raise ConfigError(str(e)) from None
