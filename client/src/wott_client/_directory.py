"""A W3C Thing Description Directory, read: the ``/things`` listing and JSONPath search.

The listing is paged by the server; the client follows ``Link: <...>; rel="next"``
until there is none, so it neither knows nor guesses the page size. Following a
directory opens each Tactile Thing's streams and merges them into one iterator of
``(thing, item)``; each stream resumes on its own.
"""

from __future__ import annotations

from collections.abc import AsyncGenerator
from contextlib import aclosing
from typing import Any
from urllib.parse import urlencode, urljoin

import httpx

from ._errors import TransportError
from ._frames import Item
from ._merge import merge
from ._td import is_tactile
from ._thing import AsyncThing, get_json

__all__ = ["AsyncDirectory"]


class AsyncDirectory:
    def __init__(self, url: str, http: httpx.AsyncClient, page_size: int | None = None) -> None:
        self.url = url if url.endswith("/") else url + "/"
        self._http = http
        self.page_size = page_size  # asked of the server (``?limit=``); None: the server's own

    def __repr__(self) -> str:
        return f"<AsyncDirectory {self.url!r}>"

    async def async_tds(self) -> list[dict[str, Any]]:
        """Every TD the directory lists, page after page."""
        out: list[dict[str, Any]] = []
        url: str | None = urljoin(self.url, "things")
        if self.page_size is not None:
            url = f"{url}?{urlencode({'limit': self.page_size})}"
        seen = set()
        while url is not None and url not in seen:
            seen.add(url)
            page, resp = await get_json(self._http, url)
            if not isinstance(page, list):
                raise TransportError(f"{url}: a TD listing is a JSON array, got {type(page).__name__}")
            out.extend(td for td in page if isinstance(td, dict))
            nxt = resp.links.get("next", {}).get("url")
            url = urljoin(url, nxt) if nxt else None
        return out

    async def async_search(self, jsonpath: str) -> list[Any]:
        """``GET /search/jsonpath?query=...``: the values matched in every TD (RFC 9535)."""
        url = urljoin(self.url, "search/jsonpath") + "?" + urlencode({"query": jsonpath})
        found, _ = await get_json(self._http, url)
        return found if isinstance(found, list) else [found]

    async def async_things(self) -> list[AsyncThing]:
        """The listed Things the client can stream (Tactile ones), by their TDs as listed."""
        return [AsyncThing(td, self._http, self.url) for td in await self.async_tds() if is_tactile(td)]

    async def async_follow(self, *, contacts: bool = True,
                           actions: bool = True) -> AsyncGenerator[tuple[AsyncThing, Item], None]:
        """Every Tactile Thing's items as they come, as ``(thing, item)``."""
        async with aclosing(self.async_follow_batches(contacts=contacts, actions=actions)) as batches:
            async for thing, batch in batches:
                for item in batch:
                    yield thing, item

    async def async_follow_batches(self, *, contacts: bool = True, actions: bool = True
                                   ) -> AsyncGenerator[tuple[AsyncThing, list[Item]], None]:
        things = await self.async_things()

        async def tagged(thing: AsyncThing) -> AsyncGenerator[tuple[AsyncThing, list[Item]], None]:
            async with aclosing(thing.async_batches(contacts=contacts, actions=actions)) as batches:
                async for batch in batches:
                    yield thing, batch

        if not things:
            return
        async with aclosing(merge([tagged(t) for t in things])) as merged:
            async for pair in merged:
                yield pair
