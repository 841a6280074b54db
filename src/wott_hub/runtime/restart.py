"""Closing a device's driver and opening it again, and retrying one that does not open: one way, everywhere.

The contract of a device's ``restart`` action (docs/devices.md), the same in the
hub's process (``hub.device_actions``) and in a worker's (``worker``): the
device's pipeline is kept, and with it the served Thing, its stream, sequence
numbers, counters and subscribers; only the driver is closed and opened again
through the plugin registry from the ``DeviceConfig`` it was opened from, with a
new processor. If it cannot be opened, the device stays ``failed`` with the
reason and is retried with the restart backoff (``opening.restart_backoff``)
until it opens, is removed or its process stops; a driver that opens with
another mesh than the served one is closed and the device fails (``Conflict``).

What differs between the two processes (how a device's pipeline is run,
stopped, and whether it is still there) is a ``DeviceHost``'s.
"""

from __future__ import annotations

import asyncio
import contextlib
from typing import TYPE_CHECKING, Protocol

from wott_hub.errors import Conflict, DriverError

from .opening import open_driver, restart_backoff
from .pipeline import RESTARTED
from .tasks import TasksById

if TYPE_CHECKING:
    from collections.abc import Iterator

    from wott_hub.drivers.base import Driver
    from wott_hub.plugins.model import DeviceConfig

    from .pipeline import DevicePipeline

__all__ = ["DeviceHost", "Restarts"]


class DeviceHost(Protocol):
    """Where a process runs its devices' pipelines: the hub's ``Devices``, a worker's devices."""

    def is_current(self, device_id: str, pipeline: DevicePipeline) -> bool:
        """Is ``pipeline`` still the one of the device served as ``device_id`` (not removed meanwhile)?"""
        ...

    async def halt(self, device_id: str) -> None:
        """Stop running the device's pipeline and close its driver."""
        ...

    def resume(self, device_id: str) -> None:
        """Run the device's pipeline again, on the driver it has now."""
        ...


class Restarts:
    """The restarts of one process's devices: one at a time per device, and the re-open retries."""

    def __init__(self, host: DeviceHost) -> None:
        self._host = host
        self._busy: set[str] = set()
        self._retries = TasksById("reopen")  # device id -> its re-open retry loop

    @contextlib.contextmanager
    def one_at_a_time(self, device_id: str) -> Iterator[None]:
        """Hold ``device_id`` for one restart; a second one meanwhile is a ``Conflict``."""
        if device_id in self._busy:
            raise Conflict(f"device {device_id!r} is being restarted already")
        self._busy.add(device_id)
        try:
            yield
        finally:
            self._busy.discard(device_id)

    async def restart(self, device_id: str, pipeline: DevicePipeline, config: DeviceConfig) -> str:
        """Close the device's driver and open it again from ``config``: its detail, or the ``DriverError``
        of the open (the device then ``failed`` and retried) or the ``Conflict`` of another mesh."""
        with self.one_at_a_time(device_id):
            self._retries.cancel(device_id)
            await self._host.halt(device_id)
            pipeline.restarting()
            try:
                driver = await open_driver(config)
            except DriverError as e:
                pipeline.failed(str(e))
                self._retries.start(device_id, self._retry(device_id, pipeline, config, str(e)))
                raise
            await self._resume(device_id, pipeline, driver)
        return RESTARTED

    async def _resume(self, device_id: str, pipeline: DevicePipeline, driver: Driver) -> None:
        try:
            pipeline.reopened(driver)
        except Conflict:  # another mesh: the TD would lie; the device has failed
            await pipeline.close()
            raise
        if self._host.is_current(device_id, pipeline):  # not removed while it opened
            self._host.resume(device_id)

    async def _retry(self, device_id: str, pipeline: DevicePipeline, config: DeviceConfig,
                     reason: str) -> None:
        """Open the device again with backoff until it opens (then it runs) or the task is cancelled."""
        backoff = restart_backoff()
        while True:
            delay = backoff.next_delay()
            pipeline.retrying(reason, backoff.attempts, delay)
            await asyncio.sleep(delay)
            try:
                driver = await open_driver(config)
            except DriverError as e:
                reason = str(e)
                continue
            if not self._host.is_current(device_id, pipeline):  # removed meanwhile
                await driver.close()
                return
            with contextlib.suppress(Conflict):  # failed, with the reason
                await self._resume(device_id, pipeline, driver)
            return

    def cancel(self, device_id: str) -> None:
        """Stop retrying ``device_id`` (it is removed, or restarted by hand)."""
        self._retries.cancel(device_id)

    async def stop(self) -> None:
        """Cancel every retry and wait until they are done."""
        await self._retries.stop()
