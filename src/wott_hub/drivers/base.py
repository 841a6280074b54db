"""What the hub needs from any device, whatever its family.

A driver describes its device once (mesh, material, shape, frame, ε: a
``DeviceDescription``) and then yields ``TactileFrame``s asynchronously. It
owns its transport (camera, serial port, network) and keeps it alive: when the
transport fails it reports ``disconnected`` with a reason, retries with
backoff and resumes yielding; it never raises out of ``frames()`` for a
transient fault. The hub stops a driver by ``close()``.
"""

from __future__ import annotations

import abc
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass
from enum import StrEnum

from wott_hub.tactile import DeviceDescription, TactileFrame

__all__ = ["Driver", "DriverError", "Health", "HealthStatus"]


class DriverError(RuntimeError):
    """A driver cannot start at all (bad config, model contract mismatch...)."""


class Health(StrEnum):
    ok = "ok"
    degraded = "degraded"  # frames flow, but something is wrong (dropped frames, bad CRCs...)
    disconnected = "disconnected"  # no frames; the driver is trying to reconnect


@dataclass(frozen=True, slots=True)
class HealthStatus:
    state: Health
    reason: str = ""
    since_ns: int = 0

    @classmethod
    def now(cls, state: Health, reason: str = "") -> HealthStatus:
        return cls(state, reason, time.time_ns())


class Driver(abc.ABC):
    """One open device. Subclasses implement ``frames``; the rest has defaults."""

    def __init__(self, description: DeviceDescription) -> None:
        self.description = description
        self._health = HealthStatus.now(Health.ok)

    @abc.abstractmethod
    def frames(self) -> AsyncIterator[TactileFrame]:
        """Yield frames as the device produces them, until ``close()``."""

    async def prepare(self) -> None:
        """Called by the hub once, after opening and before reading ``description``.

        Default: nothing, the description came with the driver. A device that can
        describe itself only over its transport (a network WoT device's mesh, read
        from its properties) does that I/O here, without blocking the loop, and
        raises ``DriverError`` if it cannot.
        """
        return None

    def health(self) -> HealthStatus:
        return self._health

    def set_health(self, state: Health, reason: str = "") -> None:
        if state != self._health.state or reason != self._health.reason:
            self._health = HealthStatus.now(state, reason)

    async def close(self) -> None:
        """Release the transport. Default: nothing to release."""
        return None
