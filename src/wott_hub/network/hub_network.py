"""``hub.network``: the directory, the registrations and mDNS, fed by what the hub serves.

It is given a ``HubPort`` (port.py) and its two config tables; it never
imports the hub.

The hub exposes and removes Things in several places (devices, the hub Thing,
replays started from the CLI or by the hub Thing's action, adopted devices);
all of them go through ``HubServer.expose`` and ``HubServer.remove``. The
network listens there (``on_expose``/``on_remove``), so every served Thing
reaches the directory and mDNS whoever exposed it, and the servient keeps
knowing nothing about directories.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any

from .directory import HubDirectory
from .discovery import HubDiscovery

if TYPE_CHECKING:
    from wott_hub.servient import ServedThing

    from .config import DirectoryConfig, DiscoveryConfig
    from .port import HubPort

__all__ = ["HubNetwork"]

log = logging.getLogger("wott_hub.network")


class HubNetwork:
    def __init__(self, hub: HubPort, directory: DirectoryConfig, discovery: DiscoveryConfig) -> None:
        self.hub = hub
        self.own_ids: set[str] = set()
        """TD ids of every Thing the hub serves and of its directory: discovery never adopts them."""
        d = directory
        self.directory = HubDirectory(hub, d) if d.enabled or d.register_to else None
        s = discovery
        self.discovery = HubDiscovery(hub, s, self.own_ids) if s.mdns or s.browse or s.directories else None
        self.started = False
        hub.listen(self._exposed, self._removed)

    def _exposed(self, served: ServedThing) -> None:
        tid = served.td.get("id")
        if isinstance(tid, str):
            self.own_ids.add(tid)
        if not self.started:
            return  # start() takes every Thing served by then
        if self.directory is not None:
            self.directory.exposed(served.td)
        if self.discovery is not None:
            self.discovery.exposed(served.id)

    def _removed(self, served: ServedThing) -> None:
        tid = served.td.get("id")
        if tid in self.own_ids and not any(t.td.get("id") == tid for t in self.hub.served()):
            self.own_ids.discard(tid)
        if not self.started:
            return
        if self.directory is not None:
            self.directory.removed(served.td)
        if self.discovery is not None:
            self.discovery.removed(served.id)

    async def start(self) -> None:
        """After the history database is open (the directory lives in it)."""
        if self.directory is not None:
            await self.directory.start()
            if self.directory.directory is not None:
                self.own_ids.add(self.directory.directory.own_id)
        self.started = True
        if self.discovery is not None:
            port = self.hub.http_port if self.directory is not None and \
                self.directory.directory is not None else None
            await self.discovery.start(port)

    async def stop(self) -> None:
        if not self.started:
            return
        self.started = False
        if self.discovery is not None:
            await self.discovery.stop()
        if self.directory is not None:
            await self.directory.stop()

    async def drain(self) -> None:
        """Wait until the directories have every change made so far."""
        if self.directory is not None:
            await self.directory.drain()

    def describe(self) -> dict[str, Any]:
        out: dict[str, Any] = {"directory": None, "registered_to": []}
        if self.directory is not None:
            out.update(self.directory.describe())
        if self.discovery is not None:
            out["discovery"] = self.discovery.describe()
        return out
