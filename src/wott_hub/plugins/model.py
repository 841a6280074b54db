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

__all__ = ["DEVICE_ID_PATTERN", "DEVICE_ID_RULE", "USB_SUBSYSTEMS", "DeviceConfig", "DeviceTable",
           "FamilyInfo", "PluginInfo", "UsbMatch", "check_device_id", "device_id_from"]

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


USB_SUBSYSTEMS = ("video4linux", "tty")
"""The udev subsystems a ``UsbMatch`` may name: a camera's /dev/videoN, a serial board's /dev/ttyACMn."""

_USB_ID = re.compile(r"^[0-9a-f]{4}$")


@dataclass(frozen=True)
class UsbMatch:
    """Which USB devices are of ``family``, by their udev properties (``wott_hub_usb_devices``).

    A device matches when it is in ``subsystem`` and every rule given holds (rules left out hold):
    ``vendor_id`` and one of ``product_ids`` (``ID_VENDOR_ID``/``ID_MODEL_ID``, 4 lower-case hex digits),
    ``model`` (``ID_MODEL`` equal, udev's spaces as ``_``), ``v4l_product`` (a part of the V4L2 name,
    ``ID_V4L_PRODUCT``). Adopted (``[usb] adopt``), it becomes the device ``<id_prefix>-<serial>``
    (``ID_SERIAL_SHORT``; default prefix: the family) of ``family``, with ``settings`` and its device
    node given as ``setting`` (``device`` for a camera, ``port`` for a serial board). ``setting`` None:
    the device is only listed, never adopted (a bridge whose device is reached another way). ``label``
    says what the device is, for ``wott-hub discover --usb``.
    """

    family: str
    subsystem: str
    label: str
    vendor_id: str | None = None
    product_ids: tuple[str, ...] = ()
    model: str | None = None
    v4l_product: str | None = None
    setting: str | None = None
    id_prefix: str = ""
    settings: Mapping[str, Any] = field(default_factory=dict)

    def problem(self) -> str | None:
        """Why this declaration can never match or be adopted, or None."""
        if self.subsystem not in USB_SUBSYSTEMS:
            return f"subsystem {self.subsystem!r} is not one of {list(USB_SUBSYSTEMS)}"
        ids = ([self.vendor_id] if self.vendor_id is not None else []) + list(self.product_ids)
        if bad := [i for i in ids if not isinstance(i, str) or not _USB_ID.match(i)]:
            return f"USB id {bad[0]!r} is not 4 lower-case hex digits"
        if self.product_ids and self.vendor_id is None:
            return "product_ids without a vendor_id"
        if self.vendor_id is None and self.model is None and self.v4l_product is None:
            return "no rule: give vendor_id, model or v4l_product"
        if self.id_prefix and device_id_from(self.id_prefix, "") != self.id_prefix:
            return f"id_prefix {self.id_prefix!r}: {DEVICE_ID_RULE}"
        if self.setting is not None and self.setting in self.settings:
            return f"setting {self.setting!r} is also in settings"
        return None

    def matches(self, subsystem: str, properties: Mapping[str, str]) -> bool:
        """Does a udev device of ``subsystem`` with ``properties`` match? (No I/O: tests give dicts.)"""
        if subsystem != self.subsystem:
            return False
        if self.vendor_id is not None and properties.get("ID_VENDOR_ID", "").lower() != self.vendor_id:
            return False
        if self.product_ids and properties.get("ID_MODEL_ID", "").lower() not in self.product_ids:
            return False
        if self.model is not None and properties.get("ID_MODEL") != self.model:
            return False
        return self.v4l_product is None or self.v4l_product in properties.get("ID_V4L_PRODUCT", "")

    @property
    def adoptable(self) -> bool:
        return self.setting is not None

    def to_dict(self) -> dict[str, Any]:
        return {"family": self.family, "subsystem": self.subsystem, "label": self.label,
                "vendor_id": self.vendor_id, "product_ids": list(self.product_ids), "model": self.model,
                "v4l_product": self.v4l_product, "setting": self.setting,
                "id_prefix": self.id_prefix or self.family, "settings": dict(self.settings)}
