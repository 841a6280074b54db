"""The binary form of an event, for high-rate consumers: ``skinDisplacement`` packets as bytes.

Two bindings carry it, both declared in the TD with the form's ``contentType``
(``events.fields.CONTENT_TYPE``, the byte layout of docs/tactile-td.md):

- ``GET /wot/<id>/events/<name>/binary``: one HTTP response that never ends
  (``subprotocol: "stream"``), the packets one after the other (each says its length);
- ``ws://.../wot/<id>/events/<name>/binary/ws``: one WebSocket binary message per packet.

Both resume as the SSE stream does: ``Last-Event-ID`` (or ``?lastEventId=``) is the ``seq`` of
the last packet the client has (every packet carries its own), and the client gets every
later record from memory or history, then the live ones. The bytes are made once per record,
by the first binary consumer (``FieldRecord.binary``); a record that is not a ``FieldRecord``
(a replay's, an embedding program's) is read from its JSON text, and one that is not a
displacement packet in that exact form is left out of the stream (its JSON is on the SSE form).
"""

from __future__ import annotations

import asyncio
import struct
from typing import Any

import tornado.web
import tornado.websocket
from tornado.iostream import StreamClosedError

from wott_hub.errors import WottHubError, http_status
from wott_hub.events.fields import FieldRecord, field_of_text, packet_bytes
from wott_hub.events.record import KIND_EVENT, Record
from wott_hub.events.subscriber import Subscriber
from wott_hub.td.forms import BINARY_EVENTS

from .context import ServingContext
from .http import BaseHandler
from .problem import write_problem
from .sending import chunk, send_now
from .things import ServedThing

__all__ = ["BinaryEventHandler", "BinaryEventSocket", "packet_of"]


def packet_of(rec: Record) -> bytes | None:
    """The binary form of ``rec`` (None: a text that is no displacement packet in the hub's form)."""
    if type(rec) is FieldRecord:
        return rec.binary()
    field = field_of_text(rec.data)
    if field is None:
        return None
    ts = int(rec.data[13:rec.data.index(",", 13)])  # '{"timeStamp":' is 13 characters: field_of_text checked
    return packet_bytes(rec.seq, ts, field)


def _binary(packets: list[bytes | None]) -> bytes:
    return b"".join([p for p in packets if p is not None])


def _thing(ctx: ServingContext, thing_id: str, name: str) -> ServedThing:
    thing = ctx.things.get(thing_id)
    if thing is None:
        raise tornado.web.HTTPError(404, reason=f"Unknown Thing {thing_id!r}")
    if name not in (thing.td.get("events") or {}) or name not in BINARY_EVENTS:
        raise tornado.web.HTTPError(404, reason=f"No binary form of event {name!r}")
    return thing


def _after(raw: str | None) -> int | None:
    if raw is None or raw.strip() == "":
        return None
    try:
        return int(raw)
    except ValueError:
        raise tornado.web.HTTPError(400, reason=f"Last-Event-ID must be an integer, got {raw!r}") from None


class BinaryEventHandler(BaseHandler):
    """The packets of one event as one endless HTTP response (chunked on HTTP/1.1)."""

    _sub: Subscriber | None = None

    def initialize(self, ctx: ServingContext) -> None:
        self.ctx = ctx

    async def get(self, thing_id: str, name: str) -> None:
        thing = _thing(self.ctx, thing_id, name)
        headers = self.request.headers
        after = _after(headers.get("Last-Event-ID") or self.get_query_argument("lastEventId", None))
        if not self.ctx.streams_ready.is_set():
            await self.ctx.streams_ready.wait()
        try:
            sub = self._sub = self.ctx.plane.subscribe(thing.id, (KIND_EVENT, name), after=after)
        except WottHubError as e:
            raise tornado.web.HTTPError(http_status(e), reason=str(e)) from None
        self.ctx.sse.add(self)
        conn = self.request.connection
        stream = conn.stream  # type: ignore[union-attr]  # tornado's HTTP1Connection
        sub.cut = stream.close  # cut off at max_pending: disconnected, its buffers let go
        try:
            self.set_header("Content-Type", BINARY_EVENTS[name])
            self.set_header("Cache-Control", "no-cache")
            self.set_header("X-Accel-Buffering", "no")
            await self.flush()  # the headers
            stream.set_nodelay(True)
            chunked = self.request.version == "HTTP/1.1"

            def write(data: bytes) -> asyncio.Future[None] | None:
                return send_now(stream, chunk(data) if chunked else data)

            def direct(rec: Record) -> bool:
                if stream.writing() or stream.closed() or sub.gap is not None:
                    return False
                packet = packet_of(rec)
                if packet is not None:
                    write(packet)
                return True

            async for batch in sub.batches(direct):
                sub.gap = None  # a binary stream cannot say it (its SSE twin does): the ids jump
                sent = write(_binary([packet_of(r) for r in batch]))
                if sent is not None:
                    await sent
        except StreamClosedError:
            pass
        finally:
            sub.close()
            self.ctx.sse.discard(self)
        if not self._finished and not stream.closed():
            self.finish()

    def heartbeat(self, now: float, every_s: float) -> None:
        """Nothing to send between packets (a binary stream has no comments)."""

    def end_stream(self) -> None:
        if self._sub is not None:
            self._sub.close()

    def on_connection_close(self) -> None:
        self.end_stream()


def _binary_frame(payload: bytes) -> bytes:
    """One unmasked, final binary frame (RFC 6455 section 5.2), as a server sends it."""
    n = len(payload)
    if n < 126:
        return struct.pack("!BB", 0x82, n) + payload
    if n <= 0xFFFF:
        return struct.pack("!BBH", 0x82, 126, n) + payload
    return struct.pack("!BBQ", 0x82, 127, n) + payload


class BinaryEventSocket(tornado.websocket.WebSocketHandler):
    """The packets of one event as WebSocket binary messages, written to the socket in batches."""

    _sub: Subscriber | None = None
    _pump: asyncio.Task[None] | None = None

    def initialize(self, ctx: ServingContext) -> None:
        self.ctx = ctx

    def check_origin(self, origin: str) -> bool:
        return True  # who may read is the gate's decision (security/gate.py), as on every route here

    def write_error(self, status_code: int, **kwargs: Any) -> None:
        write_problem(self, status_code, **kwargs)

    async def get(self, *args: Any, **kwargs: Any) -> None:
        thing = _thing(self.ctx, kwargs["thing_id"], kwargs["name"])
        if self.request.headers.get("Upgrade", "").lower() != "websocket":
            # tornado answers a plain-text 400 itself: said here as every refusal of the hub is (issue 48)
            raise tornado.web.HTTPError(400, reason=f"{self.request.path} is a WebSocket: send the upgrade "
                                                    f"handshake, or GET {self.request.path[:-3]} for the "
                                                    "packets as one HTTP response")
        after = _after(self.get_query_argument("lastEventId", None))
        if not self.ctx.streams_ready.is_set():
            await self.ctx.streams_ready.wait()
        try:
            self._sub = self.ctx.plane.subscribe(thing.id, (KIND_EVENT, kwargs["name"]), after=after)
        except WottHubError as e:
            raise tornado.web.HTTPError(http_status(e), reason=str(e)) from None
        try:
            await super().get(*args, **kwargs)
        finally:
            if self.ws_connection is None:  # the handshake failed: nothing will read this subscriber
                self._sub.close()

    def open(self, *args: Any, **kwargs: Any) -> None:
        self.set_nodelay(True)
        self.ctx.ws.add(self)
        self._pump = asyncio.ensure_future(self._run())

    async def _run(self) -> None:
        sub = self._sub
        assert sub is not None  # subscribed in get(), before the handshake completes

        conn = self.ws_connection
        if conn is not None and conn.stream is not None:
            sub.cut = conn.stream.close  # cut off at max_pending: disconnected, its buffers let go

        def frames(batch: list[Record]) -> bytes:
            return b"".join([_binary_frame(p) for p in map(packet_of, batch) if p is not None])

        try:
            async for batch in sub.batches():
                conn = self.ws_connection
                if conn is None:
                    break
                stream = conn.stream
                if getattr(conn, "_compressor", None) is None and stream is not None:
                    sent = send_now(stream, frames(batch))
                    if sent is not None:
                        await sent
                else:
                    for p in map(packet_of, batch):
                        if p is not None:
                            await self.write_message(p, binary=True)
        except (tornado.websocket.WebSocketClosedError, StreamClosedError):
            pass
        finally:
            sub.close()

    def on_message(self, message: str | bytes) -> None:
        """Nothing to ask on this socket: it only sends."""

    def on_close(self) -> None:
        if self._sub is not None:
            self._sub.close()
        self.ctx.ws.discard(self)
