"""DNS-SD names and TXT records of WoT Discovery (section 6.3), and what a browser resolves.

Things are ``_wot._tcp`` services; a Thing Description Directory is a
``_wot._tcp`` service that is also registered under the subtype
``_directory._sub._wot._tcp``. The TXT record says where the TD is (``td``, an
absolute path), what it describes (``type``: Thing or Directory, Thing when
absent) and the URL scheme (``scheme``: http when absent).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

__all__ = ["DIRECTORY_SUBTYPE", "WOT_TCP", "ServiceRecord", "instance_name", "txt_record"]

WOT_TCP = "_wot._tcp.local."
DIRECTORY_SUBTYPE = "_directory._sub._wot._tcp.local."
TCP_SCHEMES = ("http", "https", "coap+tcp", "coaps+tcp")


def txt_record(td_path: str, kind: str = "Thing", scheme: str = "http") -> dict[str, str]:
    """The TXT properties the spec requires for a TCP service."""
    if not td_path.startswith("/"):
        raise ValueError(f"td must be an absolute path, not {td_path!r}")
    if kind not in ("Thing", "Directory"):
        raise ValueError(f"type must be Thing or Directory, not {kind!r}")
    if scheme not in TCP_SCHEMES:
        raise ValueError(f"scheme must be one of {', '.join(TCP_SCHEMES)} for _wot._tcp, not {scheme!r}")
    return {"td": td_path, "type": kind, "scheme": scheme}


def instance_name(name: str) -> str:
    """``barrel-1`` -> ``barrel-1._wot._tcp.local.`` (DNS-SD instance names may contain spaces and dots)."""
    return name if name.endswith("." + WOT_TCP) else f"{name}.{WOT_TCP}"


@dataclass(frozen=True)
class ServiceRecord:
    """A resolved ``_wot._tcp`` service: enough to fetch its TD."""

    name: str  # full service instance name, e.g. "barrel-1._wot._tcp.local."
    kind: str  # "Thing" | "Directory"
    scheme: str
    td_path: str
    server: str
    port: int
    addresses: tuple[str, ...]
    properties: dict[str, str] = field(default_factory=dict)

    @property
    def instance(self) -> str:
        return self.name.removesuffix("." + WOT_TCP)

    @property
    def hosts(self) -> list[str]:
        """Each address as it goes in a URL (IPv6 in brackets); the server name when there is none."""
        return [f"[{a}]" if ":" in a else a for a in self.addresses] or [self.server.rstrip(".")]

    @property
    def host(self) -> str:
        return self.hosts[0]

    @property
    def url(self) -> str:
        """Where the TD is: scheme://address:port/td."""
        return f"{self.scheme}://{self.host}:{self.port}{self.td_path}"

    @property
    def base_url(self) -> str:
        return f"{self.scheme}://{self.host}:{self.port}/"

    @classmethod
    def from_info(cls, info: Any, is_directory: bool = False) -> ServiceRecord | None:
        """From a resolved zeroconf ``ServiceInfo``; None when it lacks what a WoT service must have."""
        if info.port is None or not info.server:
            return None
        props = {}
        for k, v in (info.properties or {}).items():
            key = k.decode("utf-8", "replace") if isinstance(k, bytes) else str(k)
            val = v.decode("utf-8", "replace") if isinstance(v, bytes) else ("" if v is None else str(v))
            props[key] = val
        td_path = props.get("td", "")
        if not td_path.startswith("/"):
            return None  # the TXT record must say where the TD is
        kind = props.get("type") or "Thing"
        if is_directory:
            kind = "Directory"
        return cls(name=info.name, kind=kind, scheme=props.get("scheme") or "http", td_path=td_path,
                   server=info.server, port=int(info.port),
                   addresses=tuple(info.parsed_scoped_addresses()), properties=props)
