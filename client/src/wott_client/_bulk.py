"""Large binary reads (a raw image's .npy, ~300 kB to 1 MB) through the standard library's ``http.client``.

Why not httpx, which every other request uses: on a 640 x 480 image httpx spent ~2.2 ms of CPU
per read (its HTTP/1.1 machinery handles a body in 64 kB pieces through several layers), the
standard library's ``HTTPConnection`` ~0.2 ms, and the read rate on loopback followed (about 70
against 420 images/s, docs/benchmarks.md "fields"). So these reads go through ``http.client``,
blocking, in a thread (``asyncio.to_thread``), on keep-alive connections kept per origin: the
event loop never waits on them. Headers (the bearer token) are the client's; errors are the
client's ``TransportError``.
"""

from __future__ import annotations

import asyncio
import http.client
import ssl
import threading
from collections.abc import Mapping
from urllib.parse import urlsplit

from ._errors import TransportError

__all__ = ["BulkReader"]


class BulkReader:
    """GETs of large bodies, each on an idle keep-alive connection to its origin (or a new one)."""

    def __init__(self, headers: Mapping[str, str] | None = None, timeout_s: float = 10.0) -> None:
        self.headers = dict(headers or {})
        self.timeout_s = timeout_s
        self._idle: dict[tuple[str, str, int], list[http.client.HTTPConnection]] = {}
        self._lock = threading.Lock()

    async def get(self, url: str, headers: Mapping[str, str] | None = None) -> tuple[int, str, bytes]:
        """(status, Content-Type, body) of ``GET url``."""
        return await asyncio.to_thread(self._get, url, {**self.headers, **(headers or {})})

    def _get(self, url: str, headers: dict[str, str]) -> tuple[int, str, bytes]:
        u = urlsplit(url)
        if u.scheme not in ("http", "https") or not u.hostname:
            raise TransportError(f"{url}: not an http(s) URL")
        origin = (u.scheme, u.hostname, u.port or (443 if u.scheme == "https" else 80))
        target = (u.path or "/") + (f"?{u.query}" if u.query else "")
        for attempt in (0, 1):  # a kept connection the server closed meanwhile: once more on a new one
            conn, reused = self._connection(origin)
            try:
                conn.request("GET", target, headers=headers)
                resp = conn.getresponse()
                body = resp.read()
            except (OSError, http.client.HTTPException) as e:
                conn.close()
                if reused and attempt == 0:
                    continue
                raise TransportError(f"{url}: {e!r}") from None
            if resp.will_close:
                conn.close()
            else:
                with self._lock:
                    self._idle.setdefault(origin, []).append(conn)
            return resp.status, resp.getheader("Content-Type", ""), body
        raise TransportError(f"{url}: no answer")  # never: the second attempt returns or raises

    def _connection(self, origin: tuple[str, str, int]) -> tuple[http.client.HTTPConnection, bool]:
        with self._lock:
            idle = self._idle.get(origin)
            if idle:
                return idle.pop(), True
        scheme, host, port = origin
        if scheme == "https":
            return http.client.HTTPSConnection(host, port, timeout=self.timeout_s,
                                               context=ssl.create_default_context()), False
        return http.client.HTTPConnection(host, port, timeout=self.timeout_s), False

    def close(self) -> None:
        with self._lock:
            conns = [c for idle in self._idle.values() for c in idle]
            self._idle.clear()
        for c in conns:
            c.close()
