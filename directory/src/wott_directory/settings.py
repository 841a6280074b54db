"""How one directory behaves: who may write, how big a TD may be, how often expired TDs go.

The same settings serve the standalone ``wott-directory`` command and a hub
that embeds the directory, so nothing here knows about sockets: the embedding
server says where it listens and the directory derives its public URL from that.

Declared once, like the hub's own tables, with ``wott_configspec`` (the distribution
both use, so their errors read alike): each field's type carries its bounds
(``Annotated[int, Meta(ge=1, le=10_000)]``) and its description. ``DirectorySettings``
stays a frozen dataclass (what embedding programs build and ``dataclasses.replace``);
the msgspec ``Struct`` derived from it (``TABLE``) checks every value when the settings
are made, from the command line or in Python, and gives the JSON Schema
(``settings_schema``). A NaN, an infinity, a wrong type or a value out of bounds is
``wott_configspec``'s ``ConfigError``, this distribution's one config error, naming the
setting: ``page_size: a whole number, got 0; must be from 1 to 10000``. The directory
does not depend on wott_hub; a hub that embeds it builds these settings from its already
checked ``[directory]`` table and translates a ``ConfigError`` from here into its own
once (``wott_hub.network.config.embedded_directory_settings``).
"""

from __future__ import annotations

import ipaddress
import uuid
from dataclasses import dataclass, replace
from typing import Annotated, Any

from msgspec import Meta
from wott_configspec import ConfigError, check, json_schema, table_of

__all__ = ["TABLE", "ConfigError", "DirectorySettings", "is_loopback", "settings_schema"]


def is_loopback(host: str) -> bool:
    """True for 127.0.0.0/8, ::1 and ``localhost``: addresses no other machine can reach."""
    host = host.strip("[]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


@dataclass(frozen=True)
class DirectorySettings:
    """Everything configurable about a directory; every field has a safe default."""

    base_url: Annotated[str, Meta(description=(
        "Public URL of the directory API, ending in /; the TD's base and the Link headers use it."))] \
        = "http://127.0.0.1:8090/"
    title: Annotated[str, Meta(description="Title of the directory's own TD.")] \
        = "wott-hub Thing Description Directory"
    thing_id: Annotated[str, Meta(description=(
        "Id of the directory's own TD; default: a UUID derived from base_url (stable across restarts)."))] \
        | None = None
    token: Annotated[str, Meta(description=(
        "Bearer token that authorises writes (and reads when protect_reads)."))] | None = None
    open_writes: Annotated[bool, Meta(description=(
        "Let loopback clients write without a token. Refused unless the directory is bound to loopback."))] \
        = False
    protect_reads: Annotated[bool, Meta(description=(
        "Require the token for listing, retrieval, search and events too "
        "(the directory's TD stays open)."))] = False
    max_body_bytes: Annotated[int, Meta(ge=1024, le=2**30, description="Largest accepted TD, bytes.")] \
        = 2 * 1024 * 1024
    page_size: Annotated[int, Meta(ge=1, le=10_000, description=(
        "Largest page the listing returns; a larger limit is capped and the rest follows a next link."))] \
        = 100
    purge_interval: Annotated[float, Meta(gt=0, le=3600, description=(
        "Seconds between sweeps for expired TDs (they disappear at most this late)."))] = 1.0
    event_retention: Annotated[int, Meta(ge=0, le=10_000_000, description=(
        "How many past events are kept for Last-Event-ID replay."))] = 10_000
    max_store_bytes: Annotated[int, Meta(ge=1024 * 1024, le=2**40, description=(
        "Stored TDs in total, bytes of JSON; a write from a client that would pass it is refused (413). "
        "The embedding application's own TDs always pass."))] = 128 * 1024 * 1024
    max_event_bytes: Annotated[int, Meta(ge=0, le=2**40, description=(
        "Past events kept for Last-Event-ID replay in total, bytes of JSON (a created TD, an update's "
        "diff); the oldest go first, whatever event_retention allows."))] = 16 * 1024 * 1024
    sse_keepalive: Annotated[float, Meta(gt=0, le=3600, description=(
        "Seconds between keep-alive comments on an idle event stream."))] = 15.0
    sse_queue: Annotated[int, Meta(ge=1, le=10_000_000, description=(
        "Events buffered per slow SSE client before it is disconnected (it resumes with Last-Event-ID)."))] \
        = 10_000
    max_query_length: Annotated[int, Meta(ge=1, le=1_000_000, description=(
        "Longest search query (JSONPath, XPath, SPARQL), characters."))] = 4096
    freeze_gc: Annotated[bool, Meta(description=(
        "Move the TDs out of the cyclic garbage collector's reach (gc.freeze)."))] = False
    """Move the TDs out of the cyclic garbage collector's reach (``gc.freeze``) after loading and
    every ``freeze_every`` writes. A full collection walks every object, ~0.5-3 s with 10,000 TDs
    in memory, and stalls the IOLoop; TDs are acyclic JSON trees, freed by reference counting
    anyway. Process-wide, so off by default in a library; the standalone command turns it on."""
    freeze_every: Annotated[int, Meta(ge=1, le=10_000_000, description=(
        "Writes between two gc.freeze calls (freeze_gc)."))] = 1000

    def __post_init__(self) -> None:
        if not self.base_url.endswith("/"):
            object.__setattr__(self, "base_url", self.base_url + "/")
        check(self, TABLE, "")
        if self.token is not None and not self.token.strip():
            raise ConfigError("token: empty; leave it unset to have no token")

    @property
    def own_id(self) -> str:
        return self.thing_id or f"urn:uuid:{uuid.uuid5(uuid.NAMESPACE_URL, self.base_url)}"

    def check_bind(self, host: str) -> None:
        """Refuse open writes on an address other machines can reach."""
        if self.open_writes and not is_loopback(host):
            raise ConfigError(
                f"open_writes is only allowed when bound to loopback, not {host!r}: set a token instead")

    def with_base_url(self, base_url: str) -> DirectorySettings:
        return replace(self, base_url=base_url)


TABLE = table_of(DirectorySettings, "DirectoryTable")
"""The msgspec Struct that checks ``DirectorySettings``: read a TOML table with ``wott_configspec.read``."""


def settings_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of the directory's settings: bounds, defaults, descriptions."""
    return json_schema(TABLE)
