"""Opening a device through its plugin, in the hub's process or a worker's, and the pace of retrying.

Every call into the plugin here (the open hook, ``prepare``, reading
``description``, ``close``) is isolated (``wott_hub.plugins.isolation``): any
failure is a ``DriverError`` naming the device, never an exception of the
plugin's escaping into the hub.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from wott_hub.drivers.backoff import Backoff
from wott_hub.errors import DriverError
from wott_hub.plugins.isolation import attempt, attempt_async
from wott_hub.tactile import DeviceDescription

if TYPE_CHECKING:
    from wott_hub.drivers.base import Driver
    from wott_hub.plugins.model import DeviceConfig
    from wott_hub.plugins.registry import Registry

__all__ = ["CLOSE_TIMEOUT_S", "open_driver", "restart_backoff"]

log = logging.getLogger("wott_hub.hub")

CLOSE_TIMEOUT_S = 5.0
"""A driver's ``close()`` that has not returned by then is abandoned and reported: a stop waits no longer."""


def restart_backoff() -> Backoff:
    """The pacing of every retry of a device: a driver that raises, one that fails to open (at start, on
    a restart, ``restart.Restarts``): 0.5 s doubling to 30 s."""
    return Backoff(initial_s=0.5, cap_s=30.0, jitter=0.0)


async def open_driver(cfg: DeviceConfig, registry: Registry | None = None) -> Driver:
    """Open and prepare the device ``cfg`` (a ``DeviceConfig``) through its plugin, here or in a worker.

    Any failure is a ``DriverError`` naming the device: the plugin's own
    ``DriverError`` as it is, a bug as ``"<what> raised <Type>: <message>"``
    (logged once with its traceback). A driver that fails after opening is closed.
    """
    if registry is None:
        from wott_hub.plugins import get_registry

        registry = get_registry()
    driver: Driver = registry.open_device(cfg)  # the registry isolates the hook call (isolation.py)
    fault = (await attempt_async("prepare()", driver.prepare)).fault
    if fault is None:
        fault = attempt("description", _description_of, driver).fault
    if fault is None:
        return driver
    error = fault.error
    await attempt_async("close()", driver.close, timeout_s=CLOSE_TIMEOUT_S)
    if isinstance(error, DriverError):
        raise error
    log.error("device %s: %s", cfg.id, fault.reason, exc_info=(type(error), error, error.__traceback__))
    raise DriverError(f"device {cfg.id!r}: {fault.reason}") from error


def _description_of(driver: Driver) -> DeviceDescription:
    desc = driver.description
    if not isinstance(desc, DeviceDescription):
        raise TypeError(f"is a {type(desc).__name__}, not a DeviceDescription")
    return desc
