"""Everything a driver-plugin author imports, from one module: ``from wott_hub.plugin_api import ...``.

This is the plugin author's contract with the hub (docs/plugins.md). The names
below are kept stable; the modules they are defined in are internal and may be
moved or split at any time, so a plugin that imports them directly can break
on any release. The first-party plugins (``plugins/*``) import from here only,
and a test (tests/plugins/test_public_api.py) keeps it so.

What is here, by the job it does in a plugin:

- hooks: ``hookimpl``, ``DeviceConfig`` (what ``wott_hub_open_device`` is given),
  ``FamilyInfo`` (what ``wott_hub_families`` returns), ``UsbMatch`` (what
  ``wott_hub_usb_devices`` returns), ``naming_device`` (prefixes
  a ``DriverError`` with the device and family);
- the driver contract: ``Driver``, ``Health``, ``HealthStatus`` and the optional
  capabilities a driver may declare (``Retargetable``, ``Tareable``,
  ``Recalibratable``, ``NoisyAtRest``, ``ReportsUnavailableNodes``, ``ServesRawSignals``
  with its ``RawSignal`` descriptions and ``RawSample`` values); ``Backoff`` to reconnect a
  transport;
- errors, all in the hub's one tree (``WottHubError``): ``SettingsError`` for a
  setting that cannot open a device, ``DriverError`` for a device that cannot be
  opened or run, ``InvalidInput`` for data that can never be right as given
  (``FrameError``, ``MeshError``, ``SceneError`` are kinds of it); a plugin's own
  public error classes derive from one of these;
- settings: a family's settings as a ``SettingsModel`` (fields with ``Meta``
  bounds; ``settings_schema`` gives its JSON Schema, ``read_settings`` checks a
  table against it, ``SettingsTable`` the base of a nested table, ``model_fields``
  hands a read table to a plain class;
  ``BackoffSettings`` the two reconnect settings, ``backoff`` reads them);
- the tactile domain, no I/O: ``SkinMesh`` and its builders, ``DeviceDescription``
  with ``SkinShape``, ``CoordinateFrame``, ``Material`` and ``NodeSignal`` (what the node
  vectors measure), ``TactileFrame``;
  ``Indenter`` / ``indent`` (contact mechanics for simulators); ``Scene``
  (scripted scenes a simulator plays).

A leaf: no module of ``wott_hub`` imports this one, so it can never take part in
an import cycle. It imports nothing heavy (no cv2, onnxruntime, the hub or the
servient): a plugin module importing it stays cheap to load.
"""

from __future__ import annotations

from wott_hub.drivers.backoff import Backoff
from wott_hub.drivers.base import (
    Driver,
    DriverError,
    Health,
    HealthStatus,
    NoisyAtRest,
    RawSample,
    RawSignal,
    Recalibratable,
    ReportsUnavailableNodes,
    Retargetable,
    ServesRawSignals,
    Tareable,
)
from wott_hub.errors import InvalidInput, SettingsError, WottHubError
from wott_hub.plugins.hookspecs import hookimpl
from wott_hub.plugins.model import DeviceConfig, FamilyInfo, UsbMatch
from wott_hub.plugins.naming import naming_device
from wott_hub.plugins.settings import (
    BackoffSettings,
    Meta,
    SettingsModel,
    SettingsTable,
    backoff,
    model_fields,
    read_settings,
    settings_schema,
)
from wott_hub.sim.scene import Scene, SceneError
from wott_hub.tactile import (
    MATERIALS,
    CoordinateFrame,
    DeviceDescription,
    FrameError,
    Material,
    MeasuredContact,
    MeshError,
    NodeSignal,
    SkinMesh,
    SkinShape,
    TactileFrame,
    barrel,
    cylinder,
    flat_pad,
    taclink_barrel,
)
from wott_hub.tactile.indentation import Indenter, indent

__all__ = [
    "MATERIALS",
    "Backoff",
    "BackoffSettings",
    "CoordinateFrame",
    "DeviceConfig",
    "DeviceDescription",
    "Driver",
    "DriverError",
    "FamilyInfo",
    "FrameError",
    "Health",
    "HealthStatus",
    "Indenter",
    "InvalidInput",
    "Material",
    "MeasuredContact",
    "MeshError",
    "Meta",
    "NodeSignal",
    "NoisyAtRest",
    "RawSample",
    "RawSignal",
    "Recalibratable",
    "ReportsUnavailableNodes",
    "Retargetable",
    "Scene",
    "SceneError",
    "ServesRawSignals",
    "SettingsError",
    "SettingsModel",
    "SettingsTable",
    "SkinMesh",
    "SkinShape",
    "TactileFrame",
    "Tareable",
    "UsbMatch",
    "WottHubError",
    "backoff",
    "barrel",
    "cylinder",
    "flat_pad",
    "hookimpl",
    "indent",
    "model_fields",
    "naming_device",
    "read_settings",
    "settings_schema",
    "taclink_barrel",
]
