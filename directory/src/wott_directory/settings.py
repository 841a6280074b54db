"""How one directory behaves: who may write, how big a TD may be, how often expired TDs go.

The same settings serve the standalone ``wott-directory`` command and a hub
that embeds the directory, so nothing here knows about sockets: the embedding
server says where it listens and the directory derives its public URL from that.
"""

from __future__ import annotations

import ipaddress
import uuid
from dataclasses import dataclass, replace

__all__ = ["ConfigError", "DirectorySettings", "is_loopback"]


class ConfigError(ValueError):
    """Settings that would make the directory unsafe or unusable."""


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

    base_url: str = "http://127.0.0.1:8090/"
    """Public URL of the directory API, ending in ``/``; the TD's ``base`` and the Link headers use it."""
    title: str = "wott-hub Thing Description Directory"
    thing_id: str | None = None
    """Id of the directory's own TD; default: a UUID derived from ``base_url`` (stable across restarts)."""
    token: str | None = None
    """Bearer token that authorises writes (and reads when ``protect_reads``)."""
    open_writes: bool = False
    """Let loopback clients write without a token. Refused unless the directory is bound to loopback."""
    protect_reads: bool = False
    """Require the token for listing, retrieval, search and events too (the directory's TD stays open)."""
    max_body_bytes: int = 2 * 1024 * 1024
    page_size: int = 100
    """Largest page the listing returns; a larger ``limit`` is capped and the rest follows a next link."""
    purge_interval: float = 1.0
    """Seconds between sweeps for expired TDs (they disappear at most this late)."""
    event_retention: int = 10_000
    """How many past events are kept for ``Last-Event-ID`` replay."""
    sse_keepalive: float = 15.0
    sse_queue: int = 10_000
    """Events buffered per slow SSE client before it is disconnected (it resumes with Last-Event-ID)."""
    max_query_length: int = 4096
    freeze_gc: bool = False
    """Move the TDs out of the cyclic garbage collector's reach (``gc.freeze``) after loading and
    every ``freeze_every`` writes. A full collection walks every object, ~0.5-3 s with 10,000 TDs
    in memory, and stalls the IOLoop; TDs are acyclic JSON trees, freed by reference counting
    anyway. Process-wide, so off by default in a library; the standalone command turns it on."""
    freeze_every: int = 1000

    def __post_init__(self) -> None:
        if not self.base_url.endswith("/"):
            object.__setattr__(self, "base_url", self.base_url + "/")
        if self.token is not None and not self.token.strip():
            raise ConfigError("token: empty; leave it unset to have no token")
        if self.max_body_bytes < 1024:
            raise ConfigError("max_body_bytes: at least 1024")
        if self.page_size < 1:
            raise ConfigError("page_size: at least 1")
        if self.purge_interval <= 0:
            raise ConfigError("purge_interval: must be positive")

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
