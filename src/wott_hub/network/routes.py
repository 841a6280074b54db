"""The directory's routes on the hub's HTTP port, mounted before the directory exists.

The hub serves its TDs as soon as the devices are open and opens the database
(and with it the directory) a moment later; importing the directory package
alone costs more than half a second, which must not delay the TDs. So the hub
mounts this router for the directory's paths at once, without importing
anything of the directory, and ``install``s the directory's own route table
when it is open. A request that arrives before is held (headers and body
buffered) and replayed to the real handler then, so a client asking for
``/things`` during start-up simply waits a little, as for the hub's own streams.
If the directory could not be opened, its paths answer 503.

Only tornado's public routing interfaces are used (``Router``,
``HTTPMessageDelegate``, ``Application.get_handler_delegate``).
"""

from __future__ import annotations

import asyncio
import inspect
import json
from typing import Any

import tornado.web
from tornado import httputil
from tornado.routing import PathMatches, Router

__all__ = ["DIRECTORY_PATHS", "DirectoryRouter"]

DIRECTORY_PATHS = r"(?:/things(?:/.*)?|/search/.*|/events(?:/.*)?|/\.well-known/wot)"
"""The W3C Discovery API at the host root, as ``wott_directory.directory_handlers(prefix="")``
serves it."""


class _Unavailable(tornado.web.RequestHandler):
    def prepare(self) -> None:
        self.set_status(503)
        self.set_header("Content-Type", "application/problem+json")
        self.finish(json.dumps({"type": "about:blank", "title": "Service Unavailable", "status": 503,
                                "detail": "The hub's directory could not be opened (see the hub's log)",
                                "instance": self.request.path}))


class DirectoryRouter(Router):
    def __init__(self, app: tornado.web.Application) -> None:
        self.app = app
        self.ready = asyncio.Event()
        self.rules: list[tuple[PathMatches, type, dict[str, Any]]] = []
        self._pending: set[asyncio.Task[None]] = set()

    def install(self, routes: list[tuple[Any, ...]]) -> None:
        """The directory's route table (``directory_handlers(directory)``); requests then reach it."""
        self.rules = [(PathMatches(pattern), cls, kwargs) for pattern, cls, kwargs in routes]

    def open(self) -> None:
        """From now on requests go to the installed routes (or get 503 if there are none)."""
        self.ready.set()

    def find_handler(self, request: httputil.HTTPServerRequest, **_: Any) -> httputil.HTTPMessageDelegate:
        if not self.ready.is_set():
            return _Held(self, request)
        return self.delegate(request)

    def delegate(self, request: httputil.HTTPServerRequest) -> httputil.HTTPMessageDelegate:
        if not self.rules:
            return self.app.get_handler_delegate(request, _Unavailable)
        for matcher, cls, kwargs in self.rules:
            params = matcher.match(request)
            if params is not None:
                return self.app.get_handler_delegate(request, cls, kwargs, params.get("path_args"),
                                                     params.get("path_kwargs"))
        return self.app.get_handler_delegate(request, tornado.web.ErrorHandler, {"status_code": 404})


class _Held(httputil.HTTPMessageDelegate):
    """A request that came before the directory: kept whole, then replayed to its handler."""

    def __init__(self, router: DirectoryRouter, request: httputil.HTTPServerRequest) -> None:
        self.router = router
        self.request = request
        self.start_line: Any = None
        self.headers: Any = None
        self.chunks: list[bytes] = []
        self.real: httputil.HTTPMessageDelegate | None = None
        self.closed = False

    def headers_received(self, start_line: Any, headers: httputil.HTTPHeaders) -> None:
        self.start_line, self.headers = start_line, headers

    def data_received(self, chunk: bytes) -> None:
        self.chunks.append(chunk)

    def finish(self) -> None:
        task = asyncio.ensure_future(self._replay())
        self.router._pending.add(task)
        task.add_done_callback(self.router._pending.discard)

    def on_connection_close(self) -> None:
        self.closed = True
        if self.real is not None:
            self.real.on_connection_close()

    async def _replay(self) -> None:
        await self.router.ready.wait()
        if self.closed:
            return
        real = self.real = self.router.delegate(self.request)
        result = real.headers_received(self.start_line, self.headers)
        if inspect.isawaitable(result):
            await result
        for chunk in self.chunks:
            result = real.data_received(chunk)
            if inspect.isawaitable(result):
                await result
        real.finish()
