"""The plain values that cross the plugin boundary: device configs, families, plugin reports.

They are dataclasses of built-in types, so a plugin needs nothing from the hub
but these names to describe itself, and the CLI can print them as JSON. A
``DeviceConfig`` is read from a ``[[device]]`` table declared once
(``DeviceTable``, through ``wott_hub.configspec``): its check, its error text
and its JSON Schema in docs/configuration.md.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Annotated, Any

from wott_hub.configspec import Model, read, says
from wott_hub.errors import InvalidInput, SettingsError

__all__ = ["DEVICE_ID_PATTERN", "DEVICE_ID_RULE", "DeviceConfig", "DeviceTable", "FamilyInfo", "PluginInfo",
           "check_device_id", "device_id_from"]

DEVICE_ID_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9._~-]{0,63}$"
"""A device id every binding takes as it is (module docstring)."""
_DEVICE_ID = re.compile(DEVICE_ID_PATTERN)
DEVICE_ID_RULE = ("1 to 64 letters, digits, '.', '_', '~' or '-', starting with a letter or digit "
                  "(it goes into URLs, MQTT topics and Thing ids as it is)")


def check_device_id(value: Any, where: str = "id") -> str:
    """``value`` if it is a valid device id, else ``InvalidInput`` naming ``where`` and the rule."""
    if not isinstance(value, str) or not _DEVICE_ID.match(value):
        raise InvalidInput(f"{where}: {DEVICE_ID_RULE}, got {value!r}")
    return value


def device_id_from(text: str, default: str = "device") -> str:
    """A valid device id made of ``text``: every other character becomes '-', cut to 64."""
    out = re.sub(r"[^A-Za-z0-9._~-]+", "-", text).strip("-._~")[:64].rstrip("-._~")
    return out if out and _DEVICE_ID.match(out) else default


class DeviceTable(Model, forbid_unknown_fields=False):
    """A device: id, family, and the family's settings."""

    # the other keys are the family's settings, checked against its model when the device opens
    id: Annotated[str, says(DEVICE_ID_RULE, pattern=DEVICE_ID_PATTERN,
                            description="Unique device id (not 'hub'): " + DEVICE_ID_RULE + ".")]
    family: Annotated[str, says("a non-empty string", pattern=r"\S",
                                description="The device family (a plugin's).")]


@dataclass(frozen=True)
class DeviceConfig:
    """One device of the hub: which family opens it and with which settings.

    In the hub config it is a ``[[device]]`` TOML table (``DeviceTable``): ``id``
    and ``family`` are taken out, every other key is a setting checked against
    the family's model when the device is opened.
    """

    id: str
    family: str
    settings: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def from_table(cls, table: Mapping[str, Any], where: str = "device") -> DeviceConfig:
        """Build from a ``[[device]]`` table; ``where`` names it in a ``SettingsError`` (e.g.
        ``hub.toml: device[2]``, then ``.id``)."""
        data = dict(table) if isinstance(table, Mapping) else table
        head: DeviceTable = read(DeviceTable, data, where, error=SettingsError)
        settings = {k: v for k, v in data.items() if k not in ("id", "family")}
        return cls(id=head.id, family=head.family, settings=settings)

    def to_table(self) -> dict[str, Any]:
        return {"id": self.id, "family": self.family, **self.settings}


@dataclass(frozen=True)
class FamilyInfo:
    """A device family a plugin provides.

    ``schema`` is the family's settings model (``wott_hub.plugins.settings.SettingsModel``, a
    msgspec Struct whose fields carry their bounds, defaults and descriptions): the registry
    replaces it with the model's JSON Schema (what ``wott-hub plugins families`` shows) and
    checks every device's settings against the model itself. A JSON Schema (draft 2020-12)
    dict is accepted too, for plugins written before models (``dict_schema.py``). ``plugin``
    is filled in by the registry; a plugin leaves it empty.
    """

    name: str
    description: str
    schema: dict[str, Any] | type[Any]
    plugin: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "plugin": self.plugin, "description": self.description,
                "schema": self.schema}


@dataclass(frozen=True)
class PluginInfo:
    """What ``wott-hub plugins list`` shows about one plugin, loaded or not."""

    name: str
    distribution: str | None
    version: str | None
    families: tuple[str, ...] = ()
    hooks: tuple[str, ...] = ()
    error: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "distribution": self.distribution, "version": self.version,
                "families": list(self.families), "hooks": list(self.hooks), "error": self.error}
