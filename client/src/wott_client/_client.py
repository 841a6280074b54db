"""The async entry point: one HTTP connection pool, and targets named by URL or mDNS name.

A target with a scheme (``http://...``) is a URL; anything else is an mDNS
instance name, resolved each time it is asked for (devices move).
"""

from __future__ import annotations

from types import TracebackType
from typing import Any

import httpx

from ._bulk import BulkReader
from ._directory import AsyncDirectory
from ._errors import InvalidTD, NotFound
from ._history import AsyncHistory
from ._mdns import async_resolve
from ._thing import AsyncThing, get_json

__all__ = ["AsyncClient"]


def _is_url(target: str) -> bool:
    return "://" in target


class AsyncClient:
    """``async with AsyncClient() as c: thing = await c.async_thing(url_or_name)``."""

    def __init__(self, *, timeout_s: float = 10.0, mdns_interfaces: list[str] | None = None,
                 http: httpx.AsyncClient | None = None, token: str | None = None) -> None:
        self._own = http is None
        # a hub whose TDs declare bearer security (docs/security.md): the token goes on every request
        auth = {"Authorization": f"Bearer {token}"} if token else {}
        self.http = http or httpx.AsyncClient(timeout=timeout_s, limits=httpx.Limits(max_connections=None),
                                              follow_redirects=True, headers=auth)
        self.mdns_interfaces = mdns_interfaces
        self.bulk = BulkReader(auth, timeout_s)  # raw images: large bodies (_bulk.py)

    async def __aenter__(self) -> AsyncClient:
        return self

    async def __aexit__(self, et: type[BaseException] | None, e: BaseException | None,
                        tb: TracebackType | None) -> None:
        await self.async_close()

    async def async_close(self) -> None:
        self.bulk.close()
        if self._own:
            await self.http.aclose()

    async def async_td(self, target: str) -> tuple[dict[str, Any], str]:
        """A TD and the URL it came from."""
        url = target
        if not _is_url(target):
            found = await async_resolve(target, interfaces=self.mdns_interfaces)
            if found.kind != "Thing":
                raise NotFound(f"mDNS: {target!r} is a {found.kind}, not a Thing (use async_directory)")
            url = found.url
        td, resp = await get_json(self.http, url)
        if not isinstance(td, dict):
            raise InvalidTD(f"{url}: a TD is a JSON object")
        return td, str(resp.url)

    async def async_thing(self, target: str) -> AsyncThing:
        """The Tactile Thing whose TD is at this URL, or announced under this mDNS name."""
        td, url = await self.async_td(target)
        return AsyncThing(td, self.http, url, self.bulk)

    async def async_history(self, target: str) -> AsyncHistory:
        """A wott-hub's recorded history, from its hub Thing's TD (``http://host:8080/wot/hub``)."""
        td, url = await self.async_td(target)
        return AsyncHistory(td, self.http, url)

    def thing_from_td(self, td: dict[str, Any], url: str | None = None) -> AsyncThing:
        """A Thing from a TD you already hold (relative hrefs resolve against ``base``, else ``url``)."""
        return AsyncThing(td, self.http, url)

    async def async_directory(self, target: str, page_size: int | None = None) -> AsyncDirectory:
        """A Thing Description Directory: its API's base URL, or its mDNS name."""
        if _is_url(target):
            return AsyncDirectory(target, self.http, page_size)
        found = await async_resolve(target, interfaces=self.mdns_interfaces)
        if found.kind != "Directory":
            raise NotFound(f"mDNS: {target!r} is a {found.kind}, not a Directory")
        return AsyncDirectory(found.base, self.http, page_size)
