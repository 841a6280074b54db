"""wott-hub: a gateway for fleets of tactile sensors.

This module is the face for a program that embeds the hub: build a
``HubConfig`` (``HubConfig.load(path)`` for a TOML file, or the constructor
with ``DeviceConfig``s), then ``await serve(config)`` or drive a ``Hub``
yourself (devices from the registry or your own ``Driver``, Things of your own
with ``Hub.expose_thing`` and ``Hub.publish``); every error the hub raises on
purpose is a ``WottHubError``.
A driver-plugin author imports from ``wott_hub.plugin_api`` instead.
These two modules are the public API; every other module of the package is
internal and may change in any release (docs/plugins.md, "What is public").

The names are loaded on first use (PEP 562), so ``import wott_hub`` costs
nothing and importing any submodule (``wott_hub.tactile``, a plugin's
``wott_hub.plugin_api``) does not drag the hub, the servient or the
database in with it.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

if TYPE_CHECKING:
    from wott_hub.config import HubConfig
    from wott_hub.drivers.base import Driver
    from wott_hub.errors import (
        Busy,
        ConfigError,
        Conflict,
        DriverError,
        HistoryError,
        InvalidInput,
        NotFound,
        RecordRefused,
        SettingsError,
        WorkerDied,
        WottHubError,
    )
    from wott_hub.hub.lifecycle import Hub
    from wott_hub.hub.serve import serve
    from wott_hub.plugins.model import DeviceConfig

# public name -> the internal module it lives in
_LAZY = {
    "Hub": "wott_hub.hub",
    "serve": "wott_hub.hub",
    "HubConfig": "wott_hub.config",
    "DeviceConfig": "wott_hub.plugins.model",
    "Driver": "wott_hub.drivers.base",
    "WottHubError": "wott_hub.errors",
    "Busy": "wott_hub.errors",
    "ConfigError": "wott_hub.errors",
    "Conflict": "wott_hub.errors",
    "DriverError": "wott_hub.errors",
    "HistoryError": "wott_hub.errors",
    "InvalidInput": "wott_hub.errors",
    "NotFound": "wott_hub.errors",
    "RecordRefused": "wott_hub.errors",
    "SettingsError": "wott_hub.errors",
    "WorkerDied": "wott_hub.errors",
}

__all__ = [
    "Busy",
    "ConfigError",
    "Conflict",
    "DeviceConfig",
    "Driver",
    "DriverError",
    "HistoryError",
    "Hub",
    "HubConfig",
    "InvalidInput",
    "NotFound",
    "RecordRefused",
    "SettingsError",
    "WorkerDied",
    "WottHubError",
    "__version__",
    "serve",
]


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'wott_hub' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # once loaded, a plain attribute
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
