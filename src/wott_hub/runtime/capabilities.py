"""The device actions a device declares, from its driver's optional capabilities.

Tested where the driver is (``driver_capabilities``): in the hub's process for
its own drivers, in a worker process for the worker's, which reports them when
it opens the device, so the hub declares the same actions for a device whatever
process it runs in (``action_names``; their schemas: ``wott_hub.td.actions``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from wott_hub.drivers.base import Recalibratable, Tareable
from wott_hub.td.actions import ALWAYS

if TYPE_CHECKING:
    from .handle import DeviceHandle

__all__ = ["action_names", "driver_capabilities"]


def driver_capabilities(driver: DeviceHandle) -> tuple[str, ...]:
    """The capability actions ``driver`` has (``"tare"``, ``"recalibrate"``); a worker's proxy has none
    of its own (its worker reported them)."""
    names = []
    if isinstance(driver, Tareable):
        names.append("tare")
    if isinstance(driver, Recalibratable):
        names.append("recalibrate")
    return tuple(names)


def action_names(driver: DeviceHandle, *, reopenable: bool,
                 capabilities: tuple[str, ...] | None = None) -> tuple[str, ...]:
    """The actions a device with ``driver`` declares: ``tare``/``recalibrate`` where the driver has the
    capability (``capabilities``: as a worker process reported them for its driver), ``restart`` when
    the hub can open it again (``reopenable``: it was opened from a configuration)."""
    caps = driver_capabilities(driver) if capabilities is None else capabilities
    names = []
    if "tare" in caps:
        names.append("tare")
    if reopenable:
        names.extend(ALWAYS)
    if "recalibrate" in caps:
        names.append("recalibrate")
    return tuple(names)
