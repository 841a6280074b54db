"""Announce the hub's directory and Things on mDNS/DNS-SD (WoT Discovery 6.3).

python-zeroconf publishes a subtype only as a PTR of the subtype name, never
of the parent type (python-zeroconf issues #109, #304, #1287), so a directory
registered as ``_directory._sub._wot._tcp`` alone would be invisible to a
client browsing ``_wot._tcp``. RFC 6763 section 7.1 wants both PTRs, so a
directory is registered normally under ``_wot._tcp`` and a second record set
for the subtype is added to the same responder: its PTR is answered from the
registry and announced and withdrawn here.

Each service gets its own host name (``<instance>.local.``) so that two
processes on one machine (or a device that comes back on another address) do
not mix their address records.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import re
from dataclasses import dataclass

import ifaddr
from zeroconf import ServiceInfo, Zeroconf
from zeroconf.asyncio import AsyncZeroconf

from .records import DIRECTORY_SUBTYPE, WOT_TCP, instance_name, txt_record

__all__ = ["Announcer", "default_addresses", "loopback_zeroconf"]

log = logging.getLogger("wott_hub.discovery")


def default_addresses() -> list[str]:
    """This machine's IPv4 addresses other than loopback (loopback alone if there are none)."""
    out = []
    for adapter in ifaddr.get_adapters():
        for ip in adapter.ips:
            if ip.is_IPv4 and not str(ip.ip).startswith("127."):
                out.append(str(ip.ip))
    return out or ["127.0.0.1"]


def _host_label(name: str) -> str:
    label = re.sub(r"[^A-Za-z0-9-]+", "-", name).strip("-").lower()[:55] or "wot"
    return f"{label}.local."


@dataclass
class _Published:
    info: ServiceInfo
    subtype: ServiceInfo | None


class Announcer:
    """Publishes ``_wot._tcp`` services on a zeroconf instance (sync or async) the caller owns."""

    def __init__(self, zc: Zeroconf | AsyncZeroconf, addresses: list[str] | None = None) -> None:
        self.aiozc = zc if isinstance(zc, AsyncZeroconf) else AsyncZeroconf(zc=zc)
        self.addresses = addresses or default_addresses()
        self._published: dict[str, _Published] = {}

    @property
    def names(self) -> set[str]:
        """Full instance names published (a browser on the same host uses them to skip itself)."""
        return set(self._published)

    def _info(self, type_: str, name: str, port: int, txt: dict[str, str], server: str,
              addresses: list[str]) -> ServiceInfo:
        return ServiceInfo(type_, name, port=port, properties=txt, server=server,
                           parsed_addresses=addresses)

    async def announce(self, name: str, port: int, td_path: str, kind: str = "Thing", scheme: str = "http",
                       addresses: list[str] | None = None) -> str:
        """Publish one service; returns its full instance name (renamed ``name (2)`` on a clash)."""
        txt = txt_record(td_path, kind, scheme)
        full = instance_name(name)
        info = self._info(WOT_TCP, full, port, txt, _host_label(name), addresses or self.addresses)
        await self.aiozc.async_register_service(info, allow_name_change=True)
        subtype = None
        if kind == "Directory":
            subtype = self._info(DIRECTORY_SUBTYPE, info.name, port, txt, info.server or "", addresses
                                 or self.addresses)
            self._add_subtype(subtype)
        self._published[info.name] = _Published(info, subtype)
        log.info("announced %s (%s) at %s:%d%s", info.name, kind, (addresses or self.addresses)[0], port,
                 td_path)
        return info.name

    async def announce_directory(self, name: str, port: int, td_path: str = "/.well-known/wot",
                                 scheme: str = "http") -> str:
        return await self.announce(name, port, td_path, "Directory", scheme)

    async def announce_thing(self, name: str, port: int, td_path: str, scheme: str = "http") -> str:
        return await self.announce(name, port, td_path, "Thing", scheme)

    def _add_subtype(self, sub: ServiceInfo) -> None:
        zc = self.aiozc.zeroconf
        sub.set_server_if_missing()
        zc.registry.types.setdefault(sub.type.lower(), {})[sub.key] = sub
        zc.async_send(zc.generate_service_broadcast(sub, None, broadcast_addresses=False))

    def _remove_subtype(self, sub: ServiceInfo) -> None:
        zc = self.aiozc.zeroconf
        bucket = zc.registry.types.get(sub.type.lower(), {})
        bucket.pop(sub.key, None)
        if not bucket:
            zc.registry.types.pop(sub.type.lower(), None)
        zc.async_send(zc.generate_service_broadcast(sub, 0, broadcast_addresses=False))

    async def update(self, name: str, port: int | None = None, addresses: list[str] | None = None,
                     td_path: str | None = None) -> None:
        """Move a published service (new port, address or TD path): browsers see an update."""
        pub = self._published[instance_name(name) if not name.endswith(".local.") else name]
        old = pub.info
        txt = {k.decode(): (v.decode() if v is not None else "") for k, v in old.properties.items()}
        if td_path is not None:
            txt["td"] = td_path
        addrs = addresses or old.parsed_addresses()
        info = self._info(WOT_TCP, old.name, port or old.port or 0, txt, old.server or "", addrs)
        await self.aiozc.async_update_service(info)
        pub.info = info
        if pub.subtype is not None:
            self._remove_subtype(pub.subtype)
            pub.subtype = self._info(DIRECTORY_SUBTYPE, old.name, info.port or 0, txt, info.server or "",
                                     addrs)
            self._add_subtype(pub.subtype)

    async def withdraw(self, name: str) -> None:
        """Unpublish with goodbye packets, so browsers drop the service at once."""
        full = name if name.endswith(".local.") else instance_name(name)
        pub = self._published.pop(full, None)
        if pub is None:
            return
        if pub.subtype is not None:
            self._remove_subtype(pub.subtype)
        task = await self.aiozc.async_unregister_service(pub.info)
        with contextlib.suppress(asyncio.CancelledError):
            await task

    async def close(self) -> None:
        """Withdraw everything (the zeroconf instance stays open: it is the caller's)."""
        for name in list(self._published):
            await self.withdraw(name)


def loopback_zeroconf() -> AsyncZeroconf:
    """A zeroconf instance on 127.0.0.1 only (tests, single-machine demos)."""
    return AsyncZeroconf(interfaces=["127.0.0.1"])
