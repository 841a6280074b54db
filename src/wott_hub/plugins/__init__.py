"""The driver plugin system (pluggy, modelled on datasette's): see docs/plugins.md.

Plugins are modules registered under the ``wott-hub`` entry-point
group; they implement the hooks of ``hookspecs`` with ``@hookimpl``. The hub
talks to them only through the ``Registry``.
"""

from .hookspecs import hookimpl, hookspec
from .loader import ENTRY_POINT_GROUP, ENV_VAR
from .model import DeviceConfig, FamilyInfo, PluginInfo, UsbMatch
from .naming import naming_device
from .registry import Registry, get_registry, reset_registry

__all__ = [
    "ENTRY_POINT_GROUP", "ENV_VAR", "DeviceConfig", "FamilyInfo", "PluginInfo", "Registry", "UsbMatch",
    "get_registry", "hookimpl", "hookspec", "naming_device", "reset_registry",
]
