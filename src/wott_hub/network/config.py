"""The ``[directory]`` and ``[discovery]`` tables of the hub config (docs/hub.md).

Kept apart from ``wott_hub.config`` so the hub's own table stays readable and
each key here is checked with a message naming the table and key. Nothing
here imports the directory, zeroconf or tornado: parsing a config stays cheap.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any
from urllib.parse import urlsplit

__all__ = ["DirectoryConfig", "DiscoveryConfig", "Registration", "parse_directory", "parse_discovery"]


@dataclass(frozen=True)
class Registration:
    """A remote directory the hub registers its Things into (``register_to``)."""

    url: str
    token: str | None = None


@dataclass(frozen=True)
class DirectoryConfig:
    enabled: bool = True
    """Serve a W3C WoT Thing Description Directory at the host root (/things, /events...)."""
    token: str | None = None
    """Bearer token for writes into the hub's directory. Without one, clients on loopback write
    freely when the hub listens on loopback only; otherwise the directory is read-only to others."""
    protect_reads: bool = False
    """Reads (listing, retrieval, search, events) need the token too."""
    register_to: tuple[Registration, ...] = ()
    """Directories every Thing of the hub is registered into, with a ttl, refreshed every ttl/3."""
    ttl_s: float = 60.0
    """ttl of those registrations: a hub that dies leaves its Things there at most this long."""


@dataclass(frozen=True)
class DiscoveryConfig:
    mdns: bool = True
    """Announce the directory (``_directory._sub._wot._tcp``) and each Thing (``_wot._tcp``)."""
    browse: bool = True
    """Browse mDNS for WoT Things and directories and adopt the tactile devices found."""
    interfaces: tuple[str, ...] = ()
    """Addresses of the interfaces mDNS runs on; empty: the hub's ``host`` when it is one address
    (loopback for the demo), every interface when the hub listens on all of them."""
    directories: tuple[str, ...] = ()
    """Directories whose Things are explored (listing, then their events) for devices to adopt."""
    adopt_hub_things: bool = False
    """Also adopt Things another wott-hub serves (ids ``urn:wott-hub:...``); off: they are
    served already, by their hub, and two hubs mirroring each other double every stream."""

    @classmethod
    def off(cls) -> DiscoveryConfig:
        """What ``HubConfig()`` built in Python gets: nothing on the network but the ports."""
        return cls(mdns=False, browse=False)


def _bool(value: Any, where: str) -> bool:
    if not isinstance(value, bool):
        raise _error(f"{where}: true or false, got {value!r}")
    return value


def _url(value: Any, where: str) -> str:
    if not isinstance(value, str) or urlsplit(value).scheme not in ("http", "https") \
            or not urlsplit(value).netloc:
        raise _error(f"{where}: an http(s) URL, got {value!r}")
    return value if value.endswith("/") else value + "/"


def _token(value: Any, where: str) -> str:
    if not isinstance(value, str) or not value.strip():
        raise _error(f"{where}: a non-empty string, got {value!r}")
    return value.strip()


def _error(message: str) -> Exception:
    from wott_hub.config import ConfigError  # the hub's error type; imported late (no cycle)

    return ConfigError(message)


def _check_keys(table: Any, cls: type, where: str) -> dict[str, Any]:
    if not isinstance(table, dict):
        raise _error(f"{where} must be a table")
    known = {f.name for f in fields(cls)}
    for key in table:
        if key not in known:
            raise _error(f"{where}.{key}: unknown key (known: {', '.join(sorted(known))})")
    return table


def parse_directory(table: Any, source: str) -> DirectoryConfig:
    where = f"{source}: [directory]"
    table = _check_keys(table, DirectoryConfig, where)
    values: dict[str, Any] = {}
    for key in ("enabled", "protect_reads"):
        if key in table:
            values[key] = _bool(table[key], f"{where}.{key}")
    if "token" in table:
        values["token"] = _token(table["token"], f"{where}.token")
    if "ttl_s" in table:
        ttl = table["ttl_s"]
        if isinstance(ttl, bool) or not isinstance(ttl, int | float) or not ttl > 0:
            raise _error(f"{where}.ttl_s: a positive number of seconds, got {ttl!r}")
        values["ttl_s"] = float(ttl)
    if "register_to" in table:
        entries = table["register_to"]
        if not isinstance(entries, list):
            raise _error(f"{where}.register_to: a list of directory URLs, got {entries!r}")
        regs = []
        for i, entry in enumerate(entries):
            at = f"{where}.register_to[{i}]"
            if isinstance(entry, dict):
                extra = set(entry) - {"url", "token"}
                if extra:
                    raise _error(f"{at}.{sorted(extra)[0]}: unknown key (known: token, url)")
                token = _token(entry["token"], f"{at}.token") if "token" in entry else None
                regs.append(Registration(_url(entry.get("url"), f"{at}.url"), token))
            else:
                regs.append(Registration(_url(entry, at)))
        values["register_to"] = tuple(regs)
    if values.get("protect_reads") and "token" not in values:
        raise _error(f"{where}.protect_reads: needs a token (reads would be impossible)")
    return DirectoryConfig(**values)


def parse_discovery(table: Any, source: str) -> DiscoveryConfig:
    where = f"{source}: [discovery]"
    table = _check_keys(table, DiscoveryConfig, where)
    values: dict[str, Any] = {}
    for key in ("mdns", "browse", "adopt_hub_things"):
        if key in table:
            values[key] = _bool(table[key], f"{where}.{key}")
    if "interfaces" in table:
        value = table["interfaces"]
        if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
            raise _error(f"{where}.interfaces: a list of interface addresses, got {value!r}")
        values["interfaces"] = tuple(value)
    if "directories" in table:
        value = table["directories"]
        if not isinstance(value, list):
            raise _error(f"{where}.directories: a list of directory URLs, got {value!r}")
        values["directories"] = tuple(_url(v, f"{where}.directories[{i}]") for i, v in enumerate(value))
    return DiscoveryConfig(**values)
