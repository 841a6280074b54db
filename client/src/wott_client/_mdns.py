"""mDNS names (``_wot._tcp``, WoT Discovery 6.3) -> the URL of the TD they announce.

Needs the ``mdns`` extra (zeroconf), imported only when a name is resolved.
The TXT record says where the TD is (``td``), the URL scheme and whether the
service is a Thing or a Directory (``type``).
"""

from __future__ import annotations

from dataclasses import dataclass

from ._errors import ClientError, NotFound

__all__ = ["WOT_TCP", "Resolved", "async_resolve"]

WOT_TCP = "_wot._tcp.local."


@dataclass(frozen=True)
class Resolved:
    url: str  # the TD's URL (a Directory's: its own TD)
    kind: str  # "Thing" | "Directory"
    base: str  # scheme://host:port/


def _txt(props: dict[bytes, bytes | None], key: str, default: str) -> str:
    raw = props.get(key.encode())
    return raw.decode() if raw else default


async def async_resolve(name: str, timeout_s: float = 3.0, interfaces: list[str] | None = None) -> Resolved:
    """Resolve ``barrel-1`` or ``barrel-1._wot._tcp.local.``; ``interfaces``: addresses to query on."""
    try:
        from zeroconf import IPVersion
        from zeroconf.asyncio import AsyncServiceInfo, AsyncZeroconf
    except ImportError:
        raise ClientError("resolving mDNS names needs zeroconf: pip install 'wott-client[mdns]'") from None
    full = name if name.endswith("." + WOT_TCP) else f"{name}.{WOT_TCP}"
    aiozc = AsyncZeroconf(interfaces=interfaces) if interfaces else AsyncZeroconf()
    try:
        info = AsyncServiceInfo(WOT_TCP, full)
        if not await info.async_request(aiozc.zeroconf, int(timeout_s * 1000)):
            raise NotFound(f"mDNS: nobody answers for {full!r} within {timeout_s} s")
    finally:
        await aiozc.async_close()
    addrs = sorted(info.parsed_scoped_addresses(IPVersion.All), key=lambda a: ":" in a)  # IPv4 first
    if not addrs or info.port is None:
        raise NotFound(f"mDNS: {full!r} has no address or port")
    host = f"[{addrs[0]}]" if ":" in addrs[0] else addrs[0]
    scheme = _txt(info.properties, "scheme", "http")
    base = f"{scheme}://{host}:{info.port}/"
    td = _txt(info.properties, "td", "/.well-known/wot")
    return Resolved(base.rstrip("/") + (td if td.startswith("/") else "/" + td),
                    _txt(info.properties, "type", "Thing"), base)
