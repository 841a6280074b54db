"""One SSE stream that survives disconnects: it reconnects with ``Last-Event-ID``.

The id sent is the last one parsed, and every parsed message is handed on before
a reconnect, so a server that resumes by id (as the W3C EventSource model and the
hub do) gives neither a gap nor a duplicate. Reconnects wait the server's
``retry:`` or ``reconnect_s``, doubling while the server stays unreachable (to
``max_backoff_s``). 4xx answers other than 408/429 are not retried: they will not change.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncGenerator

import httpx

from ._errors import NotFound, TransportError
from ._sse import Message, SSEParser

__all__ = ["ResumableStream", "Retry", "check_stream"]


class ResumableStream:
    __slots__ = ("_http", "last_event_id", "timeout", "max_backoff_s", "reconnect_s", "reconnects", "url")

    def __init__(self, http: httpx.AsyncClient, url: str, last_event_id: str | None = None,
                 reconnect_s: float = 0.2, max_backoff_s: float = 5.0, idle_s: float = 60.0) -> None:
        self._http = http
        self.url = url
        self.last_event_id = last_event_id
        self.reconnect_s = reconnect_s
        self.max_backoff_s = max_backoff_s
        self.reconnects = 0  # connections after the first
        # a stream silent for idle_s (servers send keep-alive comments) is taken for dead and resumed
        self.timeout = httpx.Timeout(10.0, read=idle_s)

    async def batches(self) -> AsyncGenerator[list[Message], None]:
        """The stream's messages, a list per chunk received, forever (until the caller stops)."""
        delay = self.reconnect_s
        first = True
        while True:
            if not first:
                self.reconnects += 1
            first = False
            headers = {"Accept": "text/event-stream", "Cache-Control": "no-cache"}
            if self.last_event_id is not None:
                headers["Last-Event-ID"] = self.last_event_id
            parser = SSEParser()
            connected = False
            try:
                async with self._http.stream("GET", self.url, headers=headers, timeout=self.timeout) as resp:
                    check_stream(resp, self.url, "text/event-stream", "an event stream")
                    connected = True
                    delay = self.reconnect_s
                    async for chunk in resp.aiter_bytes():
                        msgs = parser.feed(chunk)
                        if msgs:
                            for m in msgs:
                                if m.id is not None:
                                    self.last_event_id = m.id
                            yield msgs
            except (httpx.TransportError, Retry):
                pass
            if connected:  # it was up: come back at once (or when the server asked)
                retry = parser.retry_ms
                await asyncio.sleep(retry / 1000 if retry is not None else self.reconnect_s)
            else:
                await asyncio.sleep(delay)
                delay = min(delay * 2, self.max_backoff_s)

class Retry(Exception):
    """A 5xx, 408 or 429: try again later."""


def check_stream(resp: httpx.Response, url: str, media_type: str, what: str) -> None:
    """Raise what a stream's response means unless it is the ``media_type`` stream: ``NotFound``
    (404), ``TransportError`` (another 4xx, or the wrong content type, ``what`` naming the
    expected stream), ``Retry`` (a 5xx, 408, 429 or 204: come back later)."""
    code = resp.status_code
    if code == 404:
        raise NotFound(f"{url}: 404 (no such stream)")
    if 400 <= code < 500 and code not in (408, 429):
        raise TransportError(f"{url}: HTTP {code}")
    if code >= 400 or code == 204:
        raise Retry
    ctype = resp.headers.get("content-type", "")
    if media_type not in ctype:
        raise TransportError(f"{url}: not {what} (Content-Type {ctype!r})")
