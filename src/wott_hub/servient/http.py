"""HTTP handlers of the hub's own routes: TDs, catalogue, property reads, context, SSE.

Everything is served from bytes encoded once (TDs, static values) or from the
event plane (streams). Routes are a plain list (``routes``) so the hub, and
later the TD directory, can add theirs to the same tornado Application.
"""

from __future__ import annotations

import json
import time
from asyncio import Future
from collections.abc import Callable
from typing import Any

import tornado.web
from tornado.http1connection import HTTP1Connection
from tornado.httputil import HTTPServerRequest
from tornado.iostream import IOStream, StreamClosedError

from wott_hub.errors import WottHubError, http_status
from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY, Record
from wott_hub.events.subscriber import Subscriber
from wott_hub.td.builder import tactile_context
from wott_hub.td.forms import CONTEXT_PATH

from .context import ServingContext
from .forms import PREFIX
from .problem import MethodNotAllowed, write_problem
from .sending import chunk, send_now
from .things import ServedThing

__all__ = ["SSE_OPEN", "SSE_RETRY_MS", "BaseHandler", "routes"]

_CONTEXT_BYTES: bytes | None = None

SSE_RETRY_MS = 1000
"""The ``retry:`` every SSE stream starts with: how long an ``EventSource`` waits before it reconnects
(with ``Last-Event-ID``: resume loses nothing). wott-client waits it too after a drop."""
SSE_OPEN = f"retry: {SSE_RETRY_MS}\n".encode()
"""The first line of every SSE stream, sent at once (the headers go with it). A field, not a comment
line (some older clients took one for an empty message and lost the first), and no blank line after
it: it belongs to the first message, so that no client (httpx-sse neither, which dispatches any
block holding a ``retry:``) receives an empty message for it."""


class BaseHandler(tornado.web.RequestHandler):
    """For routes others mount on the hub's port (the hub Thing's actions): the same CORS headers and
    problem+json errors as the hub's own. Each takes its own route kwargs (``initialize``)."""

    def set_default_headers(self) -> None:
        # browsers (the web twin, any WoT web client) read TDs and streams cross-origin
        self.set_header("Access-Control-Allow-Origin", "*")

    def options(self, *_args: Any, **_kwargs: Any) -> None:  # routes pass named groups as kwargs
        self.set_header("Access-Control-Allow-Methods", "GET, OPTIONS")
        self.set_header("Access-Control-Allow-Headers", "Last-Event-ID, Accept, Content-Type")
        self.set_status(204)

    def write_json_text(self, text: str | bytes, content_type: str = "application/json") -> None:
        self.set_header("Content-Type", content_type)
        self.finish(text)

    def write_error(self, status_code: int, **kwargs: Any) -> None:
        # problem+json (RFC 9457), as the TD directory does, instead of tornado's HTML page
        write_problem(self, status_code, **kwargs)


class _Base(BaseHandler):
    """The hub's own routes: they serve from the ``ServingContext``."""

    def initialize(self, ctx: ServingContext) -> None:
        self.ctx = ctx

    def thing(self, thing_id: str) -> ServedThing:
        thing = self.ctx.things.get(thing_id)
        if thing is None:
            raise tornado.web.HTTPError(404, reason=f"Unknown Thing {thing_id!r}")
        return thing


class CatalogueHandler(_Base):
    """``{id: "/wot/<id>"}``, like wotpy's catalogue; ``?expanded=1`` inlines the TDs."""

    def get(self) -> None:
        if self.get_query_argument("expanded", "") not in ("", "0", "false"):
            body = b"{" + b",".join(json.dumps(t.id).encode() + b":" + t.td_bytes()
                                    for t in self.ctx.things) + b"}"
            self.write_json_text(body)
            return
        self.write_json_text(json.dumps({t.id: f"{PREFIX}/{t.id}" for t in self.ctx.things}))


class TDHandler(_Base):
    def get(self, thing_id: str) -> None:
        thing = self.thing(thing_id)
        etag = thing.etag
        self.set_header("ETag", etag)
        if self.request.headers.get("If-None-Match") == etag:
            self.set_status(304)
            self.finish()
            return
        self.write_json_text(thing.td_bytes(), "application/td+json")

    def compute_etag(self) -> None:  # we set our own, from the cached TD
        return None


class PropertyHandler(_Base):
    def get(self, thing_id: str, name: str) -> None:
        value = self.thing(thing_id).read(name)
        if value is None:
            raise tornado.web.HTTPError(404, reason=f"Unknown property {name!r}")
        self.write_json_text(value)

    def put(self, thing_id: str, name: str) -> None:
        """Every property the hub serves is read-only: say so, naming it (405, Allow: GET)."""
        if self.thing(thing_id).read(name) is None:
            raise tornado.web.HTTPError(404, reason=f"Unknown property {name!r}")
        raise MethodNotAllowed("GET, OPTIONS", f"Property {name!r} of {thing_id!r} is read-only")

    def compute_etag(self) -> None:
        return None


class AllPropertiesHandler(_Base):
    def get(self, thing_id: str) -> None:
        self.write_json_text(self.thing(thing_id).read_all())


class ContextHandler(_Base):
    def get(self) -> None:
        global _CONTEXT_BYTES
        if _CONTEXT_BYTES is None:
            _CONTEXT_BYTES = json.dumps(tactile_context(), indent=1).encode()
        self.write_json_text(_CONTEXT_BYTES, "application/ld+json")


class HealthzHandler(_Base):
    def get(self) -> None:
        self.write_json_text('{"status":"ok"}')


class _StreamHandler(_Base):
    """SSE (``Accept: text/event-stream``), else one long-poll response (wotpy's HTTP client).

    Resume: ``Last-Event-ID`` (or ``?lastEventId=``) is the last seq the client
    has; it gets every later record of the stream, from memory or history,
    then the live ones, each exactly once. A long-poll given one gets the next.

    Framing (``Record.sse``): a stream of one affordance sends unnamed messages,
    which ``EventSource.onmessage`` (node-wot, most pages) receives; a stream of
    all of a Thing's events names each message by its affordance.
    """

    _sub: Subscriber | None = None
    _last_write = 0.0
    _ended = False

    def _after(self) -> int | None:
        raw = self.request.headers.get("Last-Event-ID") or self.get_query_argument("lastEventId", None)
        if raw is None or raw.strip() == "":
            return None
        try:
            return int(raw)
        except ValueError:
            msg = f"Last-Event-ID must be an integer, got {raw!r}"
            raise tornado.web.HTTPError(400, reason=msg) from None

    async def stream(self, thing: ServedThing, interest: tuple[int, str | None]) -> None:
        after = self._after()
        sse = "text/event-stream" in self.request.headers.get("Accept", "")
        if not self.ctx.streams_ready.is_set():
            await self.ctx.streams_ready.wait()
        named = interest[1] is None  # several affordances on one stream: name each message
        try:  # e.g. a resume that needs a history known to be corrupted: 503 before any byte
            sub = self._sub = self.ctx.plane.subscribe(thing.id, interest, after=after)
        except WottHubError as e:
            raise tornado.web.HTTPError(http_status(e), reason=str(e)) from None
        self.ctx.sse.add(self)
        try:
            if not sse:
                await self._long_poll(sub)
                return
            # Nagle + delayed ACK would hold small event frames back by up to 40 ms
            stream = _iostream(self.request)
            stream.set_nodelay(True)
            sub.cut = stream.close  # cut off at max_pending: disconnected (it resumes from history)
            self.set_header("Content-Type", "text/event-stream; charset=utf-8")
            self.set_header("Cache-Control", "no-cache")
            self.set_header("X-Accel-Buffering", "no")
            self.write(SSE_OPEN)  # headers out now; a retry: field, the first message's (SSE_OPEN)
            await self.flush()
            self._last_write = time.monotonic()
            # Straight to the socket (``sending.py``), not RequestHandler.flush: a future, a done-callback
            # and a task wake-up per record on the hub's loop (docs/hub.md). Framed here as tornado frames
            # this response: in chunks for HTTP/1.1 (a 200 with no length), as is for HTTP/1.0.
            chunked = self.request.version == "HTTP/1.1"

            def write(data: bytes) -> Future[None] | None:
                return send_now(stream, chunk(data) if chunked else data)

            def direct(rec: Record) -> bool:  # push writes a record itself while the socket keeps up
                if stream.writing() or stream.closed() or sub.gap is not None:  # the gap is said first
                    return False
                if rec.trace is None:
                    write(rec.sse(named))
                else:
                    self._write_traced(write, [rec], named)
                self._last_write = time.monotonic()
                return True

            async for batch in sub.batches(direct):
                if sub.gap is not None:
                    write(f": gap: records after {sub.gap[0]} before {sub.gap[1]} are not "
                          f"recorded\n\n".encode())
                    sub.gap = None
                if batch[0].trace is None:
                    sent = write(b"".join([r.sse(named) for r in batch]))
                else:
                    sent = self._write_traced(write, batch, named)
                self._last_write = time.monotonic()
                # wait only while the socket is backed up: a slow client still holds this loop
                # back, and the subscriber's max_pending cuts it off
                if sent is not None:
                    await sent
        except StreamClosedError:
            pass
        except WottHubError as e:  # history failed mid-resume: say so, never end in silence
            if not self._headers_written:
                raise tornado.web.HTTPError(http_status(e), reason=str(e)) from None
            self.write(f": error: {e}\n\n".encode())
        finally:
            sub.close()
            self.ctx.sse.discard(self)
        if not self._finished and not _iostream(self.request).closed():
            self.finish()

    @staticmethod
    def _write_traced(write: Callable[[bytes], Future[None] | None], batch: list[Record],
                      named: bool) -> Future[None] | None:
        """Benchmarks only: stamp when each record was handed to the socket layer."""
        sent = write(b"".join([r.sse(named) for r in batch]))
        t = time.perf_counter_ns()
        for r in batch:
            if r.trace is not None:
                r.trace["sse"] = t
        return sent

    async def _long_poll(self, sub: Subscriber) -> None:
        async for batch in sub.batches():
            rec = batch[0]
            self.set_header("X-Event-Id", str(rec.seq))
            self.write_json_text(rec.data)
            return

    def head_of_stream(self) -> None:
        """``HEAD``: the stream exists (200) and its media type, nothing subscribed. node-wot 0.9.2
        opens a ``longpoll`` form with a HEAD handshake before its first GET (security/policy.py)."""
        sse = "text/event-stream" in self.request.headers.get("Accept", "")
        self.set_header("Content-Type", "text/event-stream; charset=utf-8" if sse else "application/json")
        self.set_header("Cache-Control", "no-cache")
        self.finish()

    def heartbeat(self, now: float, every_s: float) -> None:
        if self._sub is None or self._finished or now - self._last_write < every_s:
            return
        if self.request.headers.get("Accept", "").find("text/event-stream") < 0:
            return
        try:
            self.write(b": ping\n\n")
            self.flush()
            self._last_write = now
        except StreamClosedError:
            self.end_stream()

    def end_stream(self) -> None:
        if self._sub is not None:
            self._sub.close()

    def on_connection_close(self) -> None:
        self.end_stream()


class EventStreamHandler(_StreamHandler):
    def _thing(self, thing_id: str, name: str | None) -> ServedThing:
        thing = self.thing(thing_id)
        if name is not None and name not in (thing.td.get("events") or {}):
            raise tornado.web.HTTPError(404, reason=f"Unknown event {name!r}")
        return thing

    async def get(self, thing_id: str, name: str | None = None) -> None:
        await self.stream(self._thing(thing_id, name), (KIND_EVENT, name))

    def head(self, thing_id: str, name: str | None = None) -> None:
        self._thing(thing_id, name)
        self.head_of_stream()


class PropertyObserveHandler(_StreamHandler):
    def _thing(self, thing_id: str, name: str) -> ServedThing:
        thing = self.thing(thing_id)
        if not thing.is_observable(name):
            raise tornado.web.HTTPError(404, reason=f"No observable property {name!r}")
        return thing

    async def get(self, thing_id: str, name: str) -> None:
        await self.stream(self._thing(thing_id, name), (KIND_PROPERTY, name))

    def head(self, thing_id: str, name: str) -> None:
        self._thing(thing_id, name)
        self.head_of_stream()


def _iostream(request: HTTPServerRequest) -> IOStream:
    """The request's socket: tornado's HTTPServer serves every request over an HTTP1Connection."""
    conn = request.connection
    assert isinstance(conn, HTTP1Connection)
    return conn.stream


def routes(ctx: ServingContext) -> list[tuple[Any, ...]]:
    """The hub's routes of this module; ``servient.routes.routes`` puts the raw-signal and binary ones
    (whose handlers build on this module's) before them."""
    k = {"ctx": ctx}
    t = rf"{PREFIX}/(?P<thing_id>[^/]+)"
    return [
        (rf"{PREFIX}/?", CatalogueHandler, k),
        (rf"{t}/?", TDHandler, k),
        (rf"{t}/properties/?", AllPropertiesHandler, k),
        (rf"{t}/properties/(?P<name>[^/]+)/observe", PropertyObserveHandler, k),
        (rf"{t}/properties/(?P<name>[^/]+)", PropertyHandler, k),
        (rf"{t}/events/?", EventStreamHandler, k),
        (rf"{t}/events/(?P<name>[^/]+)", EventStreamHandler, k),
        (rf"/{CONTEXT_PATH}", ContextHandler, k),
        (r"/healthz", HealthzHandler, k),
    ]
