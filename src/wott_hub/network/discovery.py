"""mDNS for the hub: announce its directory and Things, adopt the WoT devices it finds.

Announcements (WoT Discovery 6.3): the directory as ``_directory._sub._wot._tcp``
(TXT ``td=/.well-known/wot``, ``type=Directory``) and every served Thing as
``_wot._tcp`` (``td=/wot/<id>``, ``type=Thing``, ``scheme=http``), on the
interfaces the hub listens on: loopback only for the demo on 127.0.0.1.

Adoption: the browser's services and the ``directories`` of the config go
through the ``Explorer``, which fetches each TD, merges introductions by TD id
and asks the plugin registry to claim it (``wott_hub_claim_td``; the built-in
``wot-remote`` family claims Tactile TDs). A claimed Thing becomes a device of
the hub (``hub.add_device``), re-exposed with the hub's own Tactile TD. When
it comes back on another address it is re-targeted, not added twice; when it
leaves (mDNS goodbye, deleted from its directory) the device is reported
``disconnected`` and stays served, ready for its return. The hub's own
services and Things are never adopted (own instance names and TD ids), nor,
unless ``adopt_hub_things``, the Things another wott-hub already serves.

Anyone on the LAN may announce a Thing, so adoption is bounded (docs/reliability.md):
a TD is read up to ``max_td_bytes``; a ``wot-remote`` device gets ``max_td_bytes`` and
``max_adopted_nodes`` as its caps (its driver refuses a larger mesh before building it,
and builds it off the event loop); a claimed id is made valid for every binding
(``plugins.model.device_id_from``).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Awaitable
from dataclasses import replace
from typing import TYPE_CHECKING, Any
from urllib.parse import urlsplit

from wott_hub.drivers.base import Retargetable
from wott_hub.drivers.remote import FAMILY as REMOTE_FAMILY
from wott_hub.plugins.model import device_id_from
from wott_hub.servient import ALL_INTERFACES

from .config import DiscoveryConfig
from .directory import OWN_ID_PREFIX

if TYPE_CHECKING:
    from zeroconf.asyncio import AsyncZeroconf

    from wott_hub.discovery import Announcer, Browser, Explorer, FoundThing

    from .port import HubPort

__all__ = ["HubDiscovery", "instance_label"]

log = logging.getLogger("wott_hub.network")


def _claim(td: dict[str, Any]) -> Any:
    """The plugin registry's adoption of a foreign TD (``wott_hub_claim_td``), None if nobody adopts it:
    the claim the hub gives its explorer (discovery itself knows no plugin)."""
    from wott_hub.plugins.registry import get_registry

    return get_registry().claim(td)


def instance_label(text: str, limit: int = 63) -> str:
    """A DNS-SD instance name of at most ``limit`` UTF-8 bytes (RFC 6763 4.1.1); dots become '-'
    (python-zeroconf does not escape them)."""
    text = text.replace(".", "-")
    raw = text.encode()[:limit]
    return raw.decode("utf-8", "ignore")


class HubDiscovery:
    def __init__(self, hub: HubPort, cfg: DiscoveryConfig, own_ids: set[str]) -> None:
        self.hub = hub
        self.cfg = cfg
        self.own_ids = own_ids  # TD ids of everything the hub serves (and its directory's), kept live
        self.zc: AsyncZeroconf | None = None
        self.announcer: Announcer | None = None
        self.browser: Browser | None = None
        self.explorer: Explorer | None = None
        self.adopted: dict[str, str] = {}  # foreign TD id -> device id
        self.unclaimed: dict[str, str] = {}  # foreign TD id -> its URL: no plugin adopts it
        self.failed: dict[str, str] = {}  # foreign TD id -> why adopting it failed
        self._names: dict[str, str] = {}  # served Thing id -> full mDNS instance name
        self._tasks: set[asyncio.Task[Any]] = set()
        self._announcing: dict[str, asyncio.Task[Any]] = {}  # served Thing id -> its announce, while it runs
        self.started = False

    # --- where mDNS runs ---------------------------------------------------------------

    def interfaces(self) -> list[str] | None:
        """Interface addresses for zeroconf; None: all of them."""
        if self.cfg.interfaces:
            return list(self.cfg.interfaces)
        host = self.hub.host
        if host in ALL_INTERFACES:
            return None
        if host == "localhost":
            return ["127.0.0.1"]
        return [host]

    def addresses(self) -> list[str] | None:
        """Addresses announced in the A records; None: the announcer's default (this host's)."""
        iface = self.interfaces()
        if iface is None:
            return None
        return [a for a in iface if ":" not in a] or iface

    # --- lifecycle -----------------------------------------------------------------------

    async def start(self, directory_port: int | None) -> None:
        cfg = self.cfg
        if cfg.mdns or cfg.browse:
            try:
                from zeroconf.asyncio import AsyncZeroconf

                iface = self.interfaces()
                self.zc = AsyncZeroconf(interfaces=iface) if iface else AsyncZeroconf()
            except Exception as e:  # no multicast here, an odd interface: the hub runs on without mDNS
                log.error("mDNS is off: zeroconf could not start on %s (%s: %s)",
                          self.interfaces() or "all interfaces", type(e).__name__, e)
        if self.zc is not None and cfg.mdns:
            from wott_hub.discovery import Announcer

            self.announcer = Announcer(self.zc, addresses=self.addresses())
            if directory_port is not None:
                self._spawn(self._announce_directory(directory_port))
            for thing in self.hub.served():
                self.exposed(thing.id)
        self.started = True  # from here on, what the explorer finds is adopted
        if (self.zc is not None and cfg.browse) or cfg.directories:
            from wott_hub.discovery import Explorer

            self.explorer = Explorer(on_found=self._found, on_updated=self._updated, on_lost=self._lost,
                                     claim=_claim, own_ids=self.own_ids, follow_directories=cfg.browse,
                                     max_td_bytes=cfg.max_td_bytes)
            if self.zc is not None and cfg.browse:
                from wott_hub.discovery import Browser

                self.browser = Browser(self.zc, self.explorer.service_added, self.explorer.service_updated,
                                       self.explorer.service_removed, ignore=self._is_own_service)
                await self.browser.start()
            for url in cfg.directories:
                self.explorer.add_directory(url)

    async def stop(self) -> None:
        """Stop adopting, withdraw every announcement (goodbyes: browsers drop them at once)."""
        self.started = False
        if self.browser is not None:
            await self.browser.stop()
        if self.explorer is not None:
            await self.explorer.close()
        for task in list(self._tasks):
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        if self.announcer is not None:
            names = list(self.announcer.names)
            await asyncio.gather(*(self.announcer.withdraw(n) for n in names), return_exceptions=True)
        if self.zc is not None:
            with contextlib.suppress(Exception):
                await self.zc.async_close()
            self.zc = None

    def _spawn(self, coro: Awaitable[object]) -> None:
        task = asyncio.ensure_future(coro)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    # --- announcing ----------------------------------------------------------------------

    def _is_own_service(self, name: str) -> bool:
        if self.announcer is None:
            return False
        return name in self.announcer.names or name in self._names.values()

    async def _announce_directory(self, port: int) -> None:
        announcer = self.announcer
        assert announcer is not None  # spawned once it is made; it stays
        try:
            await announcer.announce_directory(self._instance(self.hub.name), port,
                                               scheme=urlsplit(self.hub.http_url).scheme)  # https: TLS
        except Exception as e:
            log.warning("could not announce the directory on mDNS: %s", e)

    def _instance(self, text: str) -> str:
        """An instance name ending in the hub's id, kept whole when ``text`` is cut: two hubs (of
        one name, serving devices of one id) never announce the same instance or host name."""
        suffix = f" {self.hub.hub_id}"  # 55: the host label the announcer makes of it keeps 55 bytes
        return instance_label(text, limit=55 - len(suffix.encode())) + suffix

    def exposed(self, thing_id: str) -> None:
        if self.announcer is None:
            return
        task = asyncio.ensure_future(self._announce_thing(thing_id))
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)
        self._announcing[thing_id] = task
        task.add_done_callback(lambda t: self._announcing.pop(thing_id, None) if self._announcing.get(
            thing_id) is t else None)

    async def _announce_thing(self, thing_id: str) -> None:
        if thing_id in self._names:
            return
        announcer = self.announcer
        assert announcer is not None  # spawned once it is made; it stays
        path = urlsplit(self.hub.td_url(thing_id)).path
        name = self._instance(f"{thing_id} on {self.hub.name}")
        intended = self._names[thing_id] = f"{name}._wot._tcp.local."  # the browser skips it already
        try:
            full = await announcer.announce_thing(name, self.hub.http_port, path,
                                                  urlsplit(self.hub.http_url).scheme)
        except Exception as e:
            self._names.pop(thing_id, None)
            log.warning("could not announce %s on mDNS: %s", thing_id, e)
            return
        if self._names.get(thing_id) != intended:  # removed while it was being announced
            await announcer.withdraw(full)
            return
        self._names[thing_id] = full

    def removed(self, thing_id: str) -> None:
        announcing = self._announcing.pop(thing_id, None)
        if announcing is not None and not announcing.done():
            # still probing (~0.75 s): cancelled, it is never announced (issue 48: a replay stopped at once
            # was announced ~1.2 s later, then withdrawn); once registered, the withdraw below says goodbye
            announcing.cancel()
        name = self._names.pop(thing_id, None)
        if name is not None and self.announcer is not None:
            self._spawn(self.announcer.withdraw(name))

    # --- adopting ------------------------------------------------------------------------

    def _may_adopt(self, found: FoundThing) -> bool:
        if found.id in self.own_ids:
            return False
        if found.id.startswith(OWN_ID_PREFIX) and not self.cfg.adopt_hub_things:
            log.debug("%s is served by another wott-hub: not adopted", found.id)
            return False
        return True

    async def _found(self, found: FoundThing) -> None:
        if not self.started or not self._may_adopt(found):
            return
        if found.config is None:
            self.unclaimed[found.id] = found.url
            log.info("found %s at %s: no plugin adopts it", found.id, found.url)
            return
        await self._adopt(found)

    async def _adopt(self, found: FoundThing) -> None:
        from wott_hub.errors import WottHubError

        cfg = found.config
        device_id = self._free_id(device_id_from(cfg.id))
        if cfg.family == REMOTE_FAMILY:  # the caps of [discovery], unless the claim set its own
            cfg = replace(cfg, settings={"max_nodes": self.cfg.max_adopted_nodes,
                                         "max_td_bytes": self.cfg.max_td_bytes, **cfg.settings})
        try:
            await self.hub.add_device(replace(cfg, id=device_id))
        except Exception as e:  # DriverError, or a plugin's bug: the others are still adopted
            self.failed[found.id] = str(e) if isinstance(e, WottHubError) else f"{type(e).__name__}: {e}"
            log.warning("could not adopt %s (%s): %s", found.id, found.url, self.failed[found.id])
            return
        self.failed.pop(found.id, None)
        self.unclaimed.pop(found.id, None)
        self.adopted[found.id] = device_id
        log.info("adopted %s from %s as device %r (family %s)", found.id, found.url, device_id, cfg.family)

    def _free_id(self, wanted: str) -> str:
        served = self.hub.is_served  # every device of the hub is served
        if not served(wanted):
            return wanted
        n = 2
        while served(f"{wanted}-{n}"):
            n += 1
        return f"{wanted}-{n}"

    async def _updated(self, found: FoundThing) -> None:
        """A new TD or address of a Thing already found: re-target its device (same device id,
        same sequence for clients), or adopt it now if that had failed."""
        if not self.started or not self._may_adopt(found):
            return
        device_id = self.adopted.get(found.id)
        dev = self.hub.device(device_id) if device_id is not None else None
        if dev is None:
            if found.config is None:
                found.config = _claim(found.td)
            if found.config is not None:
                await self._adopt(found)
            return
        if isinstance(dev.driver, Retargetable):
            from wott_hub.plugins.isolation import attempt  # plugin code: its failure stays with it

            out = attempt("retarget()", dev.driver.retarget, found.td)
            if out.fault is not None:
                log.error("device %r (%s) not moved to %s: %s", device_id, found.id, found.url,
                          out.fault.reason)
                return
            log.info("device %r (%s) moved to %s", device_id, found.id, found.url)
            return
        new = _claim(found.td)  # a plugin's driver without retarget: open it again
        assert device_id is not None  # it has a device
        await self.hub.remove_device(device_id)
        self.adopted.pop(found.id, None)
        if new is not None:
            found.config = replace(new, id=device_id)
            await self._adopt(found)

    async def _lost(self, found: FoundThing) -> None:
        from wott_hub.drivers.base import Health

        device_id = self.adopted.get(found.id)
        dev = self.hub.device(device_id) if device_id is not None else None
        if dev is None:
            return
        reason = "no longer announced (mDNS goodbye or deleted from its directory)"
        dev.driver.set_health(Health.disconnected, reason)
        log.info("device %r (%s) is gone: %s", device_id, found.id, reason)

    def describe(self) -> dict[str, Any]:
        return {"mdns": self.announcer is not None, "browsing": self.browser is not None,
                "adopted": dict(self.adopted), "unclaimed": dict(self.unclaimed), "failed": dict(self.failed)}
