"""``[usb] adopt``: devices the hub opens when they are plugged in, and lets go of when unplugged.

At start the hub lists the USB devices present (``discovery.usb.scan``) and follows udev's events
(``discovery.usb.UsbMonitor``); every event is handled here, on the loop, one at a time (a queue
and one task), so an unplug and a replug of the same board never race.

- Plugged in, of an adopted family: its device config is the match's (``UsbDevice.config``: the
  node as ``port`` or ``device``, the Thing id from the serial number) and it is opened and served
  like an ``addDevice``, in the hub's process (even with ``[hub] workers``: the hub must close it
  on unplug and open it again with a node that may have changed, ``/dev/ttyACM0`` then
  ``/dev/ttyACM1``). A board that does not open is logged and left listed; the next plug tries
  again.
- Unplugged: its driver is closed and its pipeline stopped, but its Thing stays served (TD,
  properties, history, subscribers) and its health says ``disconnected``, "unplugged ...".
- Plugged in again (the same Thing id): opened again from the new node through the restart
  machinery (``runtime.restart``): the same Thing, stream and sequence numbers, and back to ``ok``.
- Of a family not adopted: listed in ``describe`` only, never opened (the skins' boards are shared
  with other uses).

A Thing id already taken by a configured device is left to that device (logged once).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from wott_hub.errors import Conflict, DriverError
from wott_hub.runtime.opening import open_driver

if TYPE_CHECKING:
    from wott_hub.discovery.usb import UsbDevice, UsbEvent, UsbMonitor
    from wott_hub.discovery.usb_config import UsbConfig

    from .devices import Devices
    from .management import FleetManagement

__all__ = ["UsbAdoption"]

log = logging.getLogger("wott_hub.hub")


@dataclass
class _Seen:
    device: UsbDevice
    plugged: bool = True
    adopted: bool = False
    note: str = ""


class UsbAdoption:
    """The USB devices of one hub: those seen, and those of an adopted family served."""

    def __init__(self, config: UsbConfig, devices: Devices, management: FleetManagement) -> None:
        self.config = config
        self.devices = devices
        self.management = management
        self.seen: dict[str, _Seen] = {}  # by sysfs path
        self._queue: asyncio.Queue[UsbEvent] = asyncio.Queue()
        self._monitor: UsbMonitor | None = None
        self._task: asyncio.Task[None] | None = None
        self._adopted: set[str] = set()  # Thing ids this adoption opened (not a configured device's)
        self.error = ""  # why no device is adopted (udev unavailable)

    # --- lifecycle ---------------------------------------------------------------------

    async def start(self) -> None:
        """Follow udev, then adopt what is plugged in already. Without udev (``UdevUnavailable``) the hub
        serves its other devices; the error is logged and in ``describe``."""
        from wott_hub.discovery.usb import UdevUnavailable, UsbEvent, UsbMonitor, scan, udev_context
        from wott_hub.plugins import get_registry

        matches = get_registry().usb_matches()
        try:
            context = await asyncio.to_thread(udev_context)
            monitor = UsbMonitor(matches, self.config.adopt, asyncio.get_running_loop(),
                                 self._queue.put_nowait, context)
            await asyncio.to_thread(monitor.start)
            self._monitor = monitor
            present = await asyncio.to_thread(scan, matches, self.config.adopt, context)
        except UdevUnavailable as e:
            self.error = str(e)
            log.error("[usb] adopt: %s; no USB device is adopted", e)
            return
        for dev in present:
            self._queue.put_nowait(UsbEvent("add", dev.sys_path, dev))
        self._task = asyncio.create_task(self._run(), name="usb-adoption")

    async def stop(self) -> None:
        monitor, self._monitor = self._monitor, None
        if monitor is not None:
            await asyncio.to_thread(monitor.stop)
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)

    async def _run(self) -> None:
        while True:
            event = await self._queue.get()
            try:
                if event.action == "add" and event.device is not None:
                    await self._plugged(event.device)
                elif event.action == "remove":
                    await self._unplugged(event.sys_path)
            except Exception:  # one device's trouble must not end the adoption of the others
                log.exception("USB %s of %s not handled", event.action, event.sys_path)

    # --- events ------------------------------------------------------------------------

    async def _plugged(self, dev: UsbDevice) -> None:
        seen = self.seen.get(dev.sys_path)
        if seen is not None and seen.plugged and seen.device.thing_id == dev.thing_id:
            return  # seen by the scan and by the monitor both
        adopt = dev.family in self.config.adopt and dev.adoptable
        seen = self.seen[dev.sys_path] = _Seen(dev, adopted=False)
        if not adopt:
            seen.note = "listed only (its family is not in [usb] adopt)"
            log.info("USB %s (%s, %s) plugged in: %s", dev.node, dev.family, dev.thing_id, seen.note)
            return
        tid = dev.thing_id
        running = self.devices.running.get(tid)
        if running is not None and running.pipeline.state != "unplugged":
            if not self._ours(tid):
                seen.note = f"not adopted: Thing id {tid!r} is a configured device's"
                log.warning("USB %s: %s", dev.node, seen.note)
                return
            if running.config is not None and running.config.settings == dev.config().settings:
                seen.adopted = True  # the same node again (a second add event): nothing to do
                return
        cfg = dev.config()
        if running is not None:
            await self._reopen(tid, cfg, dev)
        else:
            await self._adopt(cfg, dev)
        seen.adopted = tid in self.devices.running

    async def _adopt(self, cfg: Any, dev: UsbDevice) -> None:
        from wott_hub.plugins import get_registry

        try:
            cfg = get_registry().validate(cfg)
            driver = await open_driver(cfg)
            await self.devices.add_driver(driver, device_id=cfg.id, family=cfg.family,
                                          record=cfg.id not in self.devices.config.history_skip, config=cfg)
        except (DriverError, Conflict) as e:
            self.seen[dev.sys_path].note = f"not adopted: {e}"
            log.error("USB %s (%s) not adopted: %s", dev.node, cfg.id, e)
            return
        self.management.configs[cfg.id] = cfg
        self._adopted.add(cfg.id)
        log.info("USB %s plugged in: serving %s (%s)", dev.node, cfg.id, cfg.family)

    async def _reopen(self, tid: str, cfg: Any, dev: UsbDevice) -> None:
        """The board is back (perhaps on another node): its driver opened again from the new config."""
        running = self.devices.running[tid]
        running.config = cfg
        self.management.configs[tid] = cfg
        with contextlib.suppress(DriverError, Conflict):  # the pipeline says why (failed, retried)
            await self.management.actions.restarts.restart(tid, running.pipeline, cfg)
        log.info("USB %s plugged in again: %s reopened", dev.node, tid)

    async def _unplugged(self, sys_path: str) -> None:
        seen = self.seen.get(sys_path)
        if seen is None or not seen.plugged:
            return
        seen.plugged = False
        dev = seen.device
        tid = dev.thing_id
        running = self.devices.running.get(tid)
        if not seen.adopted or running is None or not self._ours(tid):
            log.info("USB %s (%s) unplugged", dev.node, dev.family)
            return
        self.management.actions.restarts.cancel(tid)  # a re-open under way would find no device
        await self.devices.halt(tid)
        running.pipeline.unplugged(f"unplugged: USB {dev.vendor_id}:{dev.product_id} serial "
                                   f"{dev.serial or '?'} left {dev.node}; it is opened again when plugged in")
        log.info("USB %s unplugged: %s disconnected", dev.node, tid)

    # --- what it knows -----------------------------------------------------------------------

    def _ours(self, tid: str) -> bool:
        return tid in self._adopted

    def describe(self) -> dict[str, Any]:
        """The USB devices seen, by Thing id: plugged or not, adopted or not, and why not."""
        out: dict[str, Any] = {}
        for seen in self.seen.values():
            row = seen.device.to_dict(adopted=seen.adopted)
            row.update(plugged=seen.plugged, note=seen.note)
            out[seen.device.thing_id] = row
        return {"adopt": list(self.config.adopt), "devices": out, "error": self.error or None}
