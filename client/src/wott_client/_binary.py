"""A binary event stream that survives disconnects, as ``ResumableStream`` does for SSE.

The stream is one endless HTTP response of self-delimiting packets (the form's
``subprotocol: "stream"``); each packet carries its seq, so after a drop the stream asks again
with ``Last-Event-ID`` = the last seq parsed and the server resumes after it (from memory or
history): no gap, no duplicate. Reconnects wait ``reconnect_s``, doubling to ``max_backoff_s``
while the server cannot be reached; 4xx answers other than 408/429 end it.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncGenerator

import httpx

from ._fields import CONTENT_TYPE, Displacement, PacketParser
from ._stream import Retry, check_stream

__all__ = ["BinaryStream"]


class BinaryStream:
    __slots__ = ("_http", "last_event_id", "max_backoff_s", "reconnect_s", "reconnects", "thing", "timeout",
                 "url")

    def __init__(self, http: httpx.AsyncClient, url: str, thing: str, last_event_id: str | None = None,
                 reconnect_s: float = 0.2, max_backoff_s: float = 5.0, idle_s: float = 60.0) -> None:
        self._http = http
        self.url = url
        self.thing = thing
        self.last_event_id = last_event_id
        self.reconnect_s = reconnect_s
        self.max_backoff_s = max_backoff_s
        self.reconnects = 0
        self.timeout = httpx.Timeout(10.0, read=idle_s)

    async def batches(self) -> AsyncGenerator[list[Displacement], None]:
        """The packets, a list per chunk received, forever (until the caller stops)."""
        delay = self.reconnect_s
        first = True
        while True:
            if not first:
                self.reconnects += 1
            first = False
            headers = {"Accept": CONTENT_TYPE}
            if self.last_event_id is not None:
                headers["Last-Event-ID"] = self.last_event_id
            parser = PacketParser(self.thing)
            connected = False
            try:
                async with self._http.stream("GET", self.url, headers=headers, timeout=self.timeout) as resp:
                    check_stream(resp, self.url, CONTENT_TYPE, "a binary displacement stream")
                    connected = True
                    delay = self.reconnect_s
                    async for chunk in resp.aiter_raw():
                        packets = parser.feed(chunk)
                        if packets:
                            self.last_event_id = packets[-1].event_id
                            yield packets
            except (httpx.TransportError, Retry):
                pass
            await asyncio.sleep(self.reconnect_s if connected else delay)
            if not connected:
                delay = min(delay * 2, self.max_backoff_s)
