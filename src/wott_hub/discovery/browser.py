"""Browse mDNS for WoT Things and directories and resolve them into ``ServiceRecord``s.

Both ``_wot._tcp`` and ``_directory._sub._wot._tcp`` are browsed and merged by
instance name, so a directory is reported once, as a Directory, whichever
PTR arrives first. A service that changes (TXT, port, address) is reported
through ``on_update`` under the same name; one that leaves (goodbye or expiry)
through ``on_remove``. Callbacks may be plain functions or coroutines.
"""

from __future__ import annotations

import asyncio
import inspect
import logging
from collections.abc import Awaitable, Callable
from typing import Any, TypeVar

from zeroconf import ServiceStateChange, Zeroconf
from zeroconf.asyncio import AsyncServiceBrowser, AsyncServiceInfo, AsyncZeroconf

from .records import DIRECTORY_SUBTYPE, WOT_TCP, ServiceRecord

__all__ = ["Browser"]

log = logging.getLogger("wott_hub.discovery")

Callback = Callable[[ServiceRecord], Any | Awaitable[Any]]
T = TypeVar("T")


class Browser:
    def __init__(self, zc: Zeroconf | AsyncZeroconf, on_add: Callback, on_update: Callback | None = None,
                 on_remove: Callback | None = None, resolve_timeout: float = 3.0,
                 ignore: Callable[[str], bool] | None = None) -> None:
        self.aiozc = zc if isinstance(zc, AsyncZeroconf) else AsyncZeroconf(zc=zc)
        self.on_add = on_add
        self.on_update = on_update
        self.on_remove = on_remove
        self.resolve_timeout = resolve_timeout
        self.ignore = ignore or (lambda name: False)
        self.records: dict[str, ServiceRecord] = {}
        self._directories: set[str] = set()
        self._browser: AsyncServiceBrowser | None = None
        self._tasks: set[asyncio.Task[None]] = set()
        self._locks: dict[str, asyncio.Lock] = {}

    async def start(self) -> None:
        self._browser = AsyncServiceBrowser(self.aiozc.zeroconf, [WOT_TCP, DIRECTORY_SUBTYPE],
                                            handlers=[self._on_change])

    async def stop(self) -> None:
        if self._browser is not None:
            await self._browser.async_cancel()
            self._browser = None
        for task in list(self._tasks):
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)

    def _on_change(self, zeroconf: Zeroconf, service_type: str, name: str,
                   state_change: ServiceStateChange) -> None:
        if self.ignore(name):
            return
        task = asyncio.ensure_future(self._handle(service_type, name, state_change))
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _handle(self, service_type: str, name: str, state: ServiceStateChange) -> None:
        lock = self._locks.setdefault(name, asyncio.Lock())
        async with lock:  # one name's events in order: add, update, remove
            try:
                if state is ServiceStateChange.Removed:
                    if service_type == DIRECTORY_SUBTYPE:
                        self._directories.discard(name)
                        return
                    rec = self.records.pop(name, None)
                    if rec is not None:
                        await _call(self.on_remove, rec)
                    return
                if service_type == DIRECTORY_SUBTYPE:
                    self._directories.add(name)
                await self._resolve(name)
            except Exception:
                log.exception("handling %s of %s failed", state.name, name)

    async def _resolve(self, name: str) -> None:
        info = AsyncServiceInfo(WOT_TCP, name)
        if not await info.async_request(self.aiozc.zeroconf, int(self.resolve_timeout * 1000)):
            log.info("could not resolve %s within %.1f s", name, self.resolve_timeout)
            return
        rec = ServiceRecord.from_info(info, is_directory=name in self._directories)
        if rec is None:
            log.info("%s is not a usable WoT service (no td path in its TXT record)", name)
            return
        old = self.records.get(name)
        self.records[name] = rec
        if old is None:
            await _call(self.on_add, rec)
        elif old != rec:
            await _call(self.on_update, rec)


async def _call(callback: Callable[[T], Any] | None, arg: T) -> None:
    """Call a callback (plain function or coroutine function) if there is one."""
    if callback is None:
        return
    result = callback(arg)
    if inspect.isawaitable(result):
        await result
