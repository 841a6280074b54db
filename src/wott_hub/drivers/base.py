"""What the hub needs from any device, whatever its family.

A driver describes its device once (mesh, material, shape, frame, ε: a
``DeviceDescription``) and then yields ``TactileFrame``s asynchronously. It
owns its transport (camera, serial port, network) and keeps it alive: when the
transport fails it reports ``disconnected`` with a reason, retries with
backoff and resumes yielding; it never raises out of ``frames()`` for a
transient fault. The hub stops a driver by ``close()``.

The contract is explicit: what every driver has is on ``Driver`` (``prepare``
included, with a default that does nothing, so the hub always awaits it); a
capability only some drivers have is a ``runtime_checkable`` protocol here
(``Retargetable``, ``Tareable``, ``NoisyAtRest``...), declared by the driver class
inheriting it and tested by the hub with ``isinstance``, never found by ``getattr``
probing: so a capability has one name, one signature and one place that documents it.
"""

from __future__ import annotations

import abc
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass
from enum import StrEnum
from typing import Any, Protocol, runtime_checkable

from wott_hub.errors import DriverError
from wott_hub.tactile import DeviceDescription, TactileFrame
from wott_hub.tactile.raw import RawSample, RawSignal

__all__ = ["Driver", "DriverError", "Health", "HealthStatus", "NoisyAtRest", "RawSample", "RawSignal",
           "Recalibratable", "ReportsUnavailableNodes", "Retargetable", "ServesRawSignals", "Tareable"]


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


@runtime_checkable
class Retargetable(Protocol):
    """A driver of a network device that can follow the device to a new address.

    Discovery calls ``retarget(td)`` when a device it already serves shows up
    again with a new Thing Description (same device, another host or port):
    the driver switches its stream to the new forms and resumes without losing
    its place. It runs on the event loop, so it must not block.
    """

    def retarget(self, td: dict[str, Any]) -> None:
        """Use ``td`` (the device's current Thing Description) from now on."""


@runtime_checkable
class Tareable(Protocol):
    """A driver that can take a new rest reference when asked (the device's ``tare`` action).

    ``tare()`` makes what the skin shows now its rest state: a vision driver
    takes its next frame as the new marker reference, a taxel array zeroes its
    offsets at the current readings. It runs on the event loop, so it must not
    block: it may only request the change, done when the next frame is read.
    Returns a short sentence saying what was done (shown to the user, recorded).
    """

    def tare(self) -> str:
        """Take a new rest reference (now, or from the next frame)."""


@runtime_checkable
class Recalibratable(Protocol):
    """A driver that can redo its calibration while running (the device's ``recalibrate`` action).

    More than a tare: what the driver learnt about its device at start is
    found again (a vision pad re-detects its marker grid, forgetting markers it
    had marked unavailable, and restarts tracking from it). Same rules as
    ``tare``: non-blocking, a request carried out on the next frame, a short
    sentence back.
    """

    def recalibrate(self) -> str:
        """Redo the calibration from the next frame (the skin at rest)."""


@runtime_checkable
class NoisyAtRest(Protocol):
    """A driver whose readings at rest are noisy (the camera skins): its floor for the below-threshold note.

    The device's processor notes in the health a press that stays between
    ``below_threshold_floor`` x ε and ε for ``below_threshold_s`` seconds (0: never),
    instead of the default floor a quiet sensor has (docs/processing.md). Read when the
    hub makes the device's processor, at open and on a restart.
    """

    below_threshold_floor: float
    below_threshold_s: float


@runtime_checkable
class ReportsUnavailableNodes(Protocol):
    """A skin some of whose nodes can have no known value (a vision skin's markers missing, merged or
    occluded at rest): served as the observable ``unavailableNodes`` property.

    ``unavailable_nodes`` holds the ids of the nodes unknown now (ascending). The hub
    reads it after every frame and compares it only when it is another object: a
    driver assigns a new list when the set changes and never changes a list in place.
    """

    unavailable_nodes: list[int]


@runtime_checkable
class ServesRawSignals(Protocol):
    """A driver whose raw signals readers may ask for: each camera's latest image, a taxel array's
    pressure grid (served as properties of the device's Thing, docs/tactile-td.md).

    ``raw_signals`` describes them once the driver is open (read when the hub serves the
    device). ``raw_sample(name)`` returns the latest value of signal ``name`` as the driver
    holds it (a reference, no copy, no encoding: the driver only keeps the last array it
    read), or None before the first frame. It runs on the event loop, so it must not block;
    the hub calls it only when a reader asks, at the reader's rate, and encodes there. An
    image is H x W (grey) or H x W x 3 in RGB order, uint8; a grid is rows x cols.
    """

    raw_signals: tuple[RawSignal, ...]

    def raw_sample(self, name: str) -> RawSample | None:
        """The latest value of signal ``name`` (one of ``raw_signals``), or None if none yet."""
