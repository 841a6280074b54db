"""What the pipeline and the hub need of a device, wherever its driver runs.

A device opened in the hub's process is its ``Driver``; one opened in a worker
process (``[hub] workers``) is seen in the hub through a ``pool.WorkerDevice``
proxy, whose frames never reach the hub (its records do). Both are a
``DeviceHandle``: the pipeline, the hub Thing's health and discovery use only
this, so none of them imports the worker pool, and the pool imports the
pipeline, never the other way round.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from wott_hub.drivers.base import Health, HealthStatus
    from wott_hub.tactile import DeviceDescription

__all__ = ["DeviceHandle"]


class DeviceHandle(Protocol):
    """A device's driver, or its worker proxy (whose health mirrors the driver's as its worker reports it)."""

    @property
    def description(self) -> DeviceDescription:
        """The device as served: mesh, material, shape, frame, ε."""
        ...

    def health(self) -> HealthStatus: ...

    def set_health(self, state: Health, reason: str = "") -> None:
        """Mark the device (discovery: gone; a proxy: the state its worker reported)."""
        ...

    async def close(self) -> None:
        """Release the device (a proxy: have its worker close it)."""
        ...
