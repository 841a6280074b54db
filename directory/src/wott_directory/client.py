"""Talk to any WoT Thing Description Directory: register, refresh, read, search, follow events.

Built on tornado only (the hub's loop), so a hub needs no other HTTP stack.
``Registrar`` keeps a set of TDs registered with a ttl and re-puts them before
they expire; when the hub dies, its TDs expire on their own.
"""

from __future__ import annotations

import asyncio
import builtins
import contextlib
import json
import logging
import random
import re
import ssl
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Any
from urllib.parse import quote, unquote, urlencode, urljoin, urlsplit

from tornado import httputil
from tornado.http1connection import HTTP1Connection, HTTP1ConnectionParameters
from tornado.httpclient import AsyncHTTPClient, HTTPClientError, HTTPRequest, HTTPResponse
from tornado.iostream import StreamClosedError
from tornado.tcpclient import TCPClient

__all__ = ["DirectoryClient", "EventStream", "ProblemError", "Registrar", "SSEEvent", "parse_links"]

log = logging.getLogger("wott_directory.client")

_LINK = re.compile(r'<([^>]*)>\s*((?:;\s*[^;,]+)*)')


class ProblemError(Exception):
    """A directory answered with an error; ``problem`` is its Problem Details body (or a stand-in)."""

    def __init__(self, status: int, problem: dict[str, Any]) -> None:
        self.status = status
        self.problem = problem
        detail = problem.get("detail") or problem.get("title") or ""
        errors = problem.get("validationErrors") or []
        extra = "".join(f"\n  {e.get('field')}: {e.get('description')}" for e in errors)
        super().__init__(f"{status} {detail}{extra}")


def parse_links(values: list[str]) -> dict[str, dict[str, str]]:
    """RFC 8288 Link header values -> {rel: {"href": ..., other params}}."""
    out: dict[str, dict[str, str]] = {}
    for value in values:
        for m in _LINK.finditer(value):
            params = {"href": m.group(1)}
            for part in m.group(2).split(";"):
                if "=" in part:
                    k, _, v = part.partition("=")
                    params[k.strip().lower()] = v.strip().strip('"')
            if "rel" in params:
                for rel in params["rel"].split():
                    out[rel] = params
    return out


@dataclass(frozen=True)
class SSEEvent:
    id: str | None
    type: str
    data: Any


class DirectoryClient:
    """An async client of one directory at ``url`` (its API base, e.g. ``http://hub:8080/``)."""

    def __init__(self, url: str, token: str | None = None, timeout: float = 10.0,
                 max_clients: int = 10) -> None:
        self.url = url if url.endswith("/") else url + "/"
        self.token = token
        self.timeout = timeout
        self.http = AsyncHTTPClient(force_instance=True, max_clients=max_clients)

    def close(self) -> None:
        self.http.close()

    def thing_url(self, thing_id: str) -> str:
        return f"{self.url}things/{quote(thing_id, safe=':')}"

    def _headers(self, extra: dict[str, str] | None = None) -> dict[str, str]:
        headers = dict(extra or {})
        if self.token:
            headers["Authorization"] = f"Bearer {self.token}"
        return headers

    async def request(self, method: str, url: str, body: Any = None, content_type: str | None = None,
                      accept: str = "application/json") -> HTTPResponse:
        """One request; a 4xx/5xx becomes ``ProblemError`` with the server's Problem Details."""
        headers = self._headers({"Accept": accept})
        data = None
        if body is not None:
            data = body if isinstance(body, bytes) else json.dumps(body).encode()
            headers["Content-Type"] = content_type or "application/json"
        req = HTTPRequest(url, method=method, headers=headers, body=data, request_timeout=self.timeout,
                          allow_nonstandard_methods=True, follow_redirects=False)
        try:
            return await self.http.fetch(req)
        except HTTPClientError as e:
            resp = e.response
            problem: dict[str, Any] = {"status": e.code, "title": e.message}
            if resp is not None and resp.body:
                with contextlib.suppress(ValueError):
                    parsed = json.loads(resp.body)
                    if isinstance(parsed, dict):
                        problem = parsed
            raise ProblemError(e.code, problem) from None

    # -- the directory API -----------------------------------------------------
    async def directory_description(self) -> dict[str, Any]:
        """The directory's own TD from ``/.well-known/wot`` at the host's root."""
        resp = await self.request("GET", urljoin(self.url, "/.well-known/wot"))
        doc: dict[str, Any] = json.loads(resp.body)
        return doc

    async def put(self, td: dict[str, Any]) -> bool:
        """Create or replace a TD with an id; True if created."""
        resp = await self.request("PUT", self.thing_url(td["id"]), td, "application/td+json")
        return resp.code == 201

    async def create(self, td: dict[str, Any]) -> str:
        """Register an anonymous TD; returns the id the directory gave it."""
        resp = await self.request("POST", f"{self.url}things", td, "application/td+json")
        location = resp.headers.get("Location", "")
        return unquote(location.rsplit("/things/", 1)[-1])

    async def get(self, thing_id: str) -> dict[str, Any]:
        resp = await self.request("GET", self.thing_url(thing_id), accept="application/td+json")
        td: dict[str, Any] = json.loads(resp.body)
        return td

    async def patch(self, thing_id: str, patch: dict[str, Any]) -> None:
        await self.request("PATCH", self.thing_url(thing_id), patch, "application/merge-patch+json")

    async def delete(self, thing_id: str) -> None:
        await self.request("DELETE", self.thing_url(thing_id))

    async def page(self, offset: int = 0,
                   limit: int | None = None) -> tuple[list[dict[str, Any]], str | None]:
        """One page of the listing and the URL of the next one (None at the end)."""
        params: dict[str, Any] = {"offset": offset} if offset else {}
        if limit is not None:
            params["limit"] = limit
        url = f"{self.url}things" + (f"?{urlencode(params)}" if params else "")
        return await self._page(url)

    async def _page(self, url: str) -> tuple[list[dict[str, Any]], str | None]:
        resp = await self.request("GET", url, accept="application/ld+json")
        links = parse_links(resp.headers.get_list("Link"))
        nxt = links.get("next", {}).get("href")
        return json.loads(resp.body), (urljoin(url, nxt) if nxt else None)

    async def list(self, limit: int | None = None) -> list[dict[str, Any]]:
        """Every TD, following the next links."""
        items, nxt = await self.page(0, limit)
        while nxt:
            more, nxt = await self._page(nxt)
            items += more
        return items

    async def search(self, query: str) -> builtins.list[Any]:
        """An RFC 9535 JSONPath query over all TDs; a bad query raises ``ProblemError`` (400)."""
        resp = await self.request("GET", f"{self.url}search/jsonpath?{urlencode({'query': query})}")
        values: builtins.list[Any] = json.loads(resp.body)
        return values

    def events(self, kind: str | None = None, diff: bool = False,
               last_event_id: str | int | None = None) -> EventStream:
        """Follow ``/events`` (or ``/events/{kind}``); use as ``async with ... as stream``."""
        path = "events" + (f"/{kind}" if kind else "") + ("?diff=true" if diff else "")
        return EventStream(self.url + path, self._headers(), last_event_id)


class EventStream:
    """A Server-Sent Events subscription read straight off a tornado HTTP/1.1 connection,
    so it can be closed at once (the pooled client cannot abort a stream)."""

    def __init__(self, url: str, headers: dict[str, str], last_event_id: str | int | None = None) -> None:
        self.url = url
        self.headers = headers
        self.last_event_id = None if last_event_id is None else str(last_event_id)
        self.queue: asyncio.Queue[SSEEvent | None] = asyncio.Queue()
        self.opened: asyncio.Future[int] = asyncio.get_event_loop().create_future()
        self._stream: Any = None
        self._task: asyncio.Task[None] | None = None
        self._buffer = ""
        self._fields: dict[str, list[str]] = {}
        self.status = 0
        self._body = b""

    async def __aenter__(self) -> EventStream:
        await self.open()
        return self

    async def __aexit__(self, *exc: Any) -> None:
        await self.close()

    async def open(self) -> None:
        """Connect and wait for the response headers (the subscription is then in place)."""
        parts = urlsplit(self.url)
        port = parts.port or (443 if parts.scheme == "https" else 80)
        tls = ssl.create_default_context() if parts.scheme == "https" else None
        self._stream = await TCPClient().connect(parts.hostname or "localhost", port, ssl_options=tls)
        conn = HTTP1Connection(self._stream, True, HTTP1ConnectionParameters(no_keep_alive=True))
        headers = httputil.HTTPHeaders({"Host": parts.netloc, "Accept": "text/event-stream",
                                         "Cache-Control": "no-cache", **self.headers})
        if self.last_event_id is not None:
            headers["Last-Event-ID"] = self.last_event_id
        target = parts.path + (f"?{parts.query}" if parts.query else "")
        conn.write_headers(httputil.RequestStartLine("GET", target, "HTTP/1.1"), headers)
        conn.finish()
        self._task = asyncio.ensure_future(self._read(conn))
        self.status = await self.opened
        if self.status != 200:
            await self._task
            problem: dict[str, Any] = {"status": self.status}
            with contextlib.suppress(ValueError):
                problem = json.loads(self._body)
            await self.close()
            raise ProblemError(self.status, problem)

    async def _read(self, conn: HTTP1Connection) -> None:
        stream = self

        class Delegate(httputil.HTTPMessageDelegate):
            def headers_received(self, start_line: Any, headers: Any) -> None:
                if not stream.opened.done():
                    stream.opened.set_result(start_line.code)

            def data_received(self, chunk: bytes) -> None:
                opened = stream.opened  # cancelled when the stream is closed under a read (a hub stopping)
                if stream.status not in (0, 200) or not opened.done() or opened.cancelled() \
                        or opened.result() != 200:
                    stream._body += chunk
                else:
                    stream._feed(chunk.decode("utf-8", "replace"))

        try:
            await conn.read_response(Delegate())
        except (StreamClosedError, OSError):
            pass
        finally:
            if not self.opened.done():
                self.opened.set_result(0)
            self.queue.put_nowait(None)

    def _feed(self, text: str) -> None:
        self._buffer += text.replace("\r\n", "\n").replace("\r", "\n")
        while "\n" in self._buffer:
            line, self._buffer = self._buffer.split("\n", 1)
            if not line:
                self._dispatch()
            elif not line.startswith(":"):
                name, _, value = line.partition(":")
                self._fields.setdefault(name, []).append(value[1:] if value.startswith(" ") else value)

    def _dispatch(self) -> None:
        fields, self._fields = self._fields, {}
        if "id" in fields:
            self.last_event_id = fields["id"][-1]
        if "data" not in fields:
            return
        raw = "\n".join(fields["data"])
        try:
            data: Any = json.loads(raw)
        except ValueError:
            data = raw
        kind = fields.get("event", ["message"])[-1]
        self.queue.put_nowait(SSEEvent(fields.get("id", [None])[-1], kind, data))

    def __aiter__(self) -> AsyncIterator[SSEEvent]:
        return self._iterate()

    async def _iterate(self) -> AsyncIterator[SSEEvent]:
        while True:
            ev = await self.queue.get()
            if ev is None:
                return
            yield ev

    async def next(self, timeout: float) -> SSEEvent:
        """The next event, or TimeoutError; EOFError if the stream ended."""
        ev = await asyncio.wait_for(self.queue.get(), timeout)
        if ev is None:
            self.queue.put_nowait(None)
            raise EOFError("the event stream ended")
        return ev

    async def close(self) -> None:
        if self._stream is not None:
            self._stream.close()
        if self._task is not None:
            with contextlib.suppress(Exception):
                await self._task


class Registrar:
    """Keeps TDs registered in a directory with a ttl, re-putting each before it expires.

    ``register`` puts the TD at once (errors are logged and retried: a
    directory that is down must not stop a hub); ``start`` runs the refresh
    loop every ``ttl * refresh`` seconds, with jitter so many hubs do not
    refresh in step. ``stop(unregister=True)`` deletes the TDs on the way out;
    if the hub dies instead, they expire ``ttl`` seconds after the last refresh.
    """

    def __init__(self, client: DirectoryClient, ttl: float = 60.0, refresh: float = 1 / 3) -> None:
        if ttl <= 0:
            raise ValueError("ttl must be positive")
        self.client = client
        self.ttl = ttl
        self.interval = ttl * refresh
        self.tds: dict[str, dict[str, Any]] = {}
        self.failures = 0
        self._task: asyncio.Task[None] | None = None

    def _with_ttl(self, td: dict[str, Any]) -> dict[str, Any]:
        """The TD with its ``registration`` replaced by ``{"ttl": ttl}`` (moved last)."""
        return {**{k: v for k, v in td.items() if k != "registration"}, "registration": {"ttl": self.ttl}}

    async def register(self, td: dict[str, Any]) -> bool:
        """Register (or replace) a TD; True if the directory accepted it now."""
        if not isinstance(td.get("id"), str):
            raise ValueError("Registrar keeps TDs by id: the TD needs an 'id'")
        self.tds[td["id"]] = self._with_ttl(td)
        return await self._put(td["id"])

    async def unregister(self, thing_id: str) -> None:
        if self.tds.pop(thing_id, None) is None:
            return
        try:
            await self.client.delete(thing_id)
        except ProblemError as e:
            if e.status != 404:
                log.warning("could not delete %s from %s: %s", thing_id, self.client.url, e)
        except OSError as e:
            log.warning("could not delete %s from %s: %s", thing_id, self.client.url, e)

    async def _put(self, thing_id: str) -> bool:
        td = self.tds.get(thing_id)
        if td is None:
            return False
        try:
            await self.client.put(td)
        except ProblemError as e:
            self.failures += 1
            log.warning("directory %s refused %s: %s", self.client.url, thing_id, e)
            return False
        except OSError as e:
            self.failures += 1
            log.warning("directory %s unreachable for %s: %s", self.client.url, thing_id, e)
            return False
        return True

    async def refresh(self) -> int:
        """Re-put every TD now; returns how many the directory accepted."""
        results = [await self._put(i) for i in list(self.tds)]
        return sum(results)

    def start(self) -> None:
        if self._task is None:
            self._task = asyncio.ensure_future(self._loop())

    async def _loop(self) -> None:
        while True:
            await asyncio.sleep(self.interval * random.uniform(0.9, 1.0))
            await self.refresh()

    async def stop(self, unregister: bool = True) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None
        if unregister:
            for thing_id in list(self.tds):
                await self.unregister(thing_id)
