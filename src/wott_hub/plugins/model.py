"""The plain values that cross the plugin boundary: device configs, families, plugin reports.

They are dataclasses of built-in types, so a plugin needs nothing from the hub
but these names to describe itself, and the CLI can print them as JSON.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from wott_hub.drivers.base import DriverError

__all__ = ["DeviceConfig", "FamilyInfo", "PluginInfo"]


@dataclass(frozen=True)
class DeviceConfig:
    """One device of the hub: which family opens it and with which settings.

    In the hub config it is a ``[[device]]`` TOML table: ``id`` and ``family``
    are taken out, every other key is a setting checked against the family's
    JSON Schema when the device is opened.
    """

    id: str
    family: str
    settings: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def from_table(cls, table: Mapping[str, Any], where: str = "device") -> DeviceConfig:
        """Build from a ``[[device]]`` table; ``where`` names it in errors (e.g. ``hub.toml: device[2]``)."""
        if not isinstance(table, Mapping):
            raise DriverError(f"{where}: expected a table, got {type(table).__name__}")
        for key in ("id", "family"):
            value = table.get(key)
            if not isinstance(value, str) or not value.strip():
                raise DriverError(f"{where}.{key}: required, a non-empty string (got {value!r})")
        settings = {k: v for k, v in table.items() if k not in ("id", "family")}
        return cls(id=table["id"], family=table["family"], settings=settings)

    def to_table(self) -> dict[str, Any]:
        return {"id": self.id, "family": self.family, **self.settings}


@dataclass(frozen=True)
class FamilyInfo:
    """A device family a plugin provides.

    ``schema`` is a JSON Schema (draft 2020-12) of the device settings; put a
    ``default`` and a ``description`` on each property: the registry fills the
    defaults in before the plugin sees the settings, and ``wott-hub plugins
    families`` shows the descriptions to users. ``plugin`` is filled in by the
    registry; a plugin leaves it empty.

    ``schema`` may instead be, and for every first-party family is, a settings model
    (``wott_hub.plugins.settings.SettingsModel``, a msgspec Struct whose fields carry their
    bounds): the registry replaces it with the model's JSON Schema and checks every device's
    settings against the model itself. The dict form stays for third-party plugins.
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
