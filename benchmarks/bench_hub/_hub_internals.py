"""Every hub internal the benchmark reaches for, imported here only.

The hub is being reshaped (``wott_hub.hub`` becomes a package; the device pipeline, the
servient adapters and the demo scene move): when a name below moves, this is the one line
to change. The groups import this module inside their functions, as they imported the hub,
so loading the package (and every client process) stays free of the hub's imports.

Public names (``wott_hub.hub.Hub``, ``wott_hub.config.HubConfig``, the lower layers
``tactile``, ``td``, ``events.record``, ``history``) are imported directly where used.
"""

from __future__ import annotations

from typing import Any

from wott_hub.drivers.base import Driver
from wott_hub.events.plane import EventPlane
from wott_hub.examples import example_device
from wott_hub.plugins import DeviceConfig
from wott_hub.servient import HubServer, ServedThing, clean_td
from wott_hub.servient.adapters import _Prebound as Prebound

__all__ = ["DeviceConfig", "Driver", "EventPlane", "HubServer", "Prebound", "ServedThing", "clean_td",
           "example_device", "hub_plane", "hub_writer", "replace_processing"]


def hub_plane(hub: Any) -> EventPlane:
    """The hub's event plane (tracing switch, per-Thing taps, publish, counters)."""
    return hub._plane


def hub_writer(hub: Any) -> Any:
    """The hub's history writer (``flush``, ``written``)."""
    return hub._history.writer


def replace_processing(device: Any, process: Any) -> None:
    """Swap the ``FrameProcessor.process`` of a device ``Hub.add_driver`` returned."""
    device.processor.process = process
