"""The ``[directory]`` and ``[discovery]`` tables of the hub config (docs/hub.md, docs/configuration.md).

Kept apart from ``wott_hub.config`` so the hub's own table stays readable. Each
field is declared once, with its bounds and its words for errors, and read by
``wott_hub.configspec`` (msgspec): a wrong value is a ``ConfigError`` naming the
file, table and key. Nothing here imports the directory, zeroconf or tornado,
nor ``wott_hub.config`` (which imports this module): parsing a config stays cheap.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, Any

from wott_hub.configspec import ConfigError, Flag, Model, bounded, check, doc, read, says, table_of

__all__ = ["DIRECTORY_TABLE", "DISCOVERY_TABLE", "DirectoryConfig", "DiscoveryConfig", "Registration",
           "embedded_directory_settings", "parse_directory", "parse_discovery"]

Token = Annotated[str, says("a non-empty string", pattern=r"\S")]
Url = Annotated[str, says("an http(s) URL", pattern=r"^https?://[^/?#\s]+")]
Urls = Annotated[tuple[Url, ...], says("a list of directory URLs")]
Interfaces = Annotated[tuple[Annotated[str, says("an interface address", min_length=1)], ...],
                       says("a list of interface addresses")]
TtlSeconds = Annotated[float, bounded("a positive number of seconds", ge=1.0, le=86_400.0)]
TdBytes = Annotated[int, says("a number of bytes", ge=1024, le=64 * 1024 * 1024)]
Nodes = Annotated[int, says("a number of nodes", ge=1, le=1_000_000)]


class RegistrationTable(Model):
    """``{ url = "...", token = "..." }`` in ``register_to``."""

    url: Url
    token: Token | None = None


@dataclass(frozen=True)
class Registration:
    """A remote directory the hub registers its Things into (``register_to``)."""

    url: str
    token: str | None = None


@dataclass(frozen=True)
class DirectoryConfig:
    enabled: Flag = field(default=True, metadata=doc(
        "Serve a W3C WoT Thing Description Directory at the host root (/things, /events...)."))
    token: Token | None = field(default=None, metadata=doc(
        "Bearer token for writes into the hub's directory. Without one, clients on loopback write "
        "freely when the hub listens on loopback only; otherwise the directory is read-only to others."))
    protect_reads: Flag = field(default=False, metadata=doc(
        "Reads (listing, retrieval, search, events) need the token too."))
    register_to: tuple[Registration, ...] = field(default=(), metadata=doc(
        "Directories every Thing of the hub is registered into, with a ttl, refreshed every ttl/3: "
        "URLs, or tables { url, token }."))
    ttl_s: TtlSeconds = field(default=60.0, metadata=doc(
        "ttl of those registrations, s: a hub that dies leaves its Things there at most this long."))

    def __post_init__(self) -> None:
        check(self, _DIRECTORY_VALUES, "[directory]")


@dataclass(frozen=True)
class DiscoveryConfig:
    mdns: Flag = field(default=True, metadata=doc(
        "Announce the directory (_directory._sub._wot._tcp) and each Thing (_wot._tcp)."))
    browse: Flag = field(default=True, metadata=doc(
        "Browse mDNS for WoT Things and directories and adopt the tactile devices found."))
    interfaces: Interfaces = field(default=(), metadata=doc(
        "Addresses of the interfaces mDNS runs on; empty: the hub's host when it is one address "
        "(loopback for the demo), every interface when the hub listens on all of them."))
    directories: Urls = field(default=(), metadata=doc(
            "Directories whose Things are explored (listing, then their events) for devices to adopt."))
    adopt_hub_things: Flag = field(default=False, metadata=doc(
        "Also adopt Things another wott-hub serves (ids urn:wott-hub:...); off: they are served "
        "already, by their hub, and two hubs mirroring each other double every stream."))
    max_td_bytes: TdBytes = field(default=1024 * 1024, metadata=doc(
        "Largest TD read from an mDNS introduction or adopted device, bytes; a longer one is not "
        "read to its end and the Thing is not adopted (anyone on the LAN may announce one)."))
    max_adopted_nodes: Nodes = field(default=20_000, metadata=doc(
        "Largest mesh of a device adopted by discovery (wot-remote), nodes (and 4 cells per node); "
        "a device with more is refused before its mesh is built."))

    @classmethod
    def off(cls) -> DiscoveryConfig:
        """What ``HubConfig()`` built in Python gets: nothing on the network but the ports."""
        return cls(mdns=False, browse=False)


DIRECTORY_TABLE = table_of(DirectoryConfig, "directory", types={
    "register_to": Annotated[
        tuple[Annotated[Url | RegistrationTable, says("an http(s) URL or a table { url, token }")], ...],
        says("a list of directory URLs")]})
"""The ``[directory]`` table as it is written in a file (JSON Schema: docs/configuration.md)."""
DISCOVERY_TABLE = table_of(DiscoveryConfig, "discovery")
"""The ``[discovery]`` table as it is written in a file."""
_DIRECTORY_VALUES = table_of(DirectoryConfig, "directory_values", exclude=("register_to",))


def _slash(url: str) -> str:
    return url if url.endswith("/") else url + "/"


def parse_directory(table: Any, source: str) -> DirectoryConfig:
    where = f"{source}: [directory]"
    t = read(DIRECTORY_TABLE, table, where)
    regs = tuple(Registration(_slash(r)) if isinstance(r, str) else
                 Registration(_slash(r.url), r.token.strip() if r.token else None) for r in t.register_to)
    if t.protect_reads and t.token is None:
        raise ConfigError(f"{where}.protect_reads: needs a token (reads would be impossible)")
    return DirectoryConfig(enabled=t.enabled, token=t.token.strip() if t.token else None,
                           protect_reads=t.protect_reads, register_to=regs, ttl_s=float(t.ttl_s))


def parse_discovery(table: Any, source: str) -> DiscoveryConfig:
    t = read(DISCOVERY_TABLE, table, f"{source}: [discovery]")
    return DiscoveryConfig(mdns=t.mdns, browse=t.browse, interfaces=t.interfaces,
                           directories=tuple(_slash(u) for u in t.directories),
                           adopt_hub_things=t.adopt_hub_things, max_td_bytes=t.max_td_bytes,
                           max_adopted_nodes=t.max_adopted_nodes)


def embedded_directory_settings(**values: Any) -> Any:
    """``wott_directory.DirectorySettings(**values)`` for the directory the hub embeds.

    The directory is its own distribution with its own (single) ``ConfigError``;
    the hub raises only ``wott_hub.errors.ConfigError``, so the one translation
    happens here, where the hub turns its ``[directory]`` table into the
    directory's settings. Imported late: parsing a config never loads the directory.
    """
    from wott_directory.settings import ConfigError as DirectoryConfigError
    from wott_directory.settings import DirectorySettings

    try:
        return DirectorySettings(**values)
    except DirectoryConfigError as e:
        raise ConfigError(f"[directory]: {e}") from None
