"""HTTP routes of a device's raw signals: one read (JSON, PNG, JPEG, .npy) and a stream at a reader's rate.

``GET /wot/<id>/properties/rawImage[?format=png|jpeg|npy][&camera=<name>]``: the camera's latest
image; ``pressureGrid[?format=npy][&signal=<name>]``: a taxel grid; ``magneticField``, ``taxelSignal``,
``taxelForce`` (same parameters): a node's vectors. ``.../stream?camera=&signal=&maxRate=``: a camera's
images as ``multipart/x-mixed-replace`` JPEG parts (what a browser ``<img>`` shows live), a grid or
vectors as an SSE stream of JSON messages; at most ``maxRate`` a second and never a frame twice, each
encoded once whatever the number of readers (``runtime.raw.RawSource``). ``.../observe[?camera=&signal=]``:
the observe form every observable property has (issue 48 item 12): with ``Accept: text/event-stream`` an
SSE stream of the JSON values at the default rate, else one long-poll answer, the next frame's JSON
(after ``LONG_POLL_S`` without one: the latest), which is what wotpy 0.18's HTTP client (it requests a
form's href as it is, and cannot expand ``{?maxRate}``) reads in a loop. The TD declares them
(``td.raw``, ``td.forms``).

At most ``MAX_RAW_STREAMS`` streams are open at once on a hub (issue 48: 200 streams, or 300 a client
never read, halved the camera devices' own rates); beyond, a 503 problem+json with ``Retry-After``.

Every stream ends when its Thing stops being served (``removeDevice``, issue 48 item 7), as the event
streams do: each turn checks that the Thing it reads is still the one served under its id.

Bad input is refused before anything is read, with a 400 problem+json naming the parameter: a
``format`` the signal has not, a ``camera`` or ``signal`` the device has not, a ``maxRate`` that is not a
number in (0, ``MAX_RATE_HZ``]. A device that fails to give a sample answers 502 (it is marked, never
the hub), one with no frame yet 503 with ``Retry-After``.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time

import tornado.web
from tornado.http1connection import HTTP1Connection
from tornado.httputil import HTTPServerRequest
from tornado.iostream import StreamClosedError

from wott_hub.errors import WottHubError
from wott_hub.tactile.raw import GRID, IMAGE, VECTORS, RawSignal
from wott_hub.td.raw import DEFAULT_RATE_HZ, MAX_RATE_HZ, raw_property
from wott_hub.types import Encoded, RawReads

from .context import ServingContext
from .http import SSE_OPEN, BaseHandler
from .things import ServedThing

__all__ = ["BOUNDARY", "LONG_POLL_S", "MAX_RAW_STREAMS", "RawObserveHandler", "RawPropertyHandler",
           "RawStreamHandler"]

BOUNDARY = "frame"
MAX_RAW_STREAMS = 16
"""Raw-signal streams open at once (each sends a camera's JPEG up to its frame rate from the hub's loop)."""
LONG_POLL_S = 10.0
"""How long a long-poll ``/observe`` waits for a frame newer than the one it found: then the latest."""
_FORMATS = {IMAGE: ("json", "png", "jpeg", "npy"), GRID: ("json", "npy"), VECTORS: ("json", "npy")}


class _RawBase(BaseHandler):
    def initialize(self, ctx: ServingContext) -> None:
        self.ctx = ctx

    def raw_of(self, thing_id: str, name: str) -> tuple[ServedThing, RawReads]:
        thing = self.ctx.things.get(thing_id)
        if thing is None:
            raise tornado.web.HTTPError(404, reason=f"Unknown Thing {thing_id!r}")
        if thing.raw is None or not thing.is_raw(name) or name not in (thing.td.get("properties") or {}):
            raise tornado.web.HTTPError(404, reason=f"Unknown property {name!r}")
        return thing, thing.raw

    def signal(self, raw: RawReads, name: str) -> RawSignal:
        """The signal the request names: a camera (``camera``), a grid or vectors (``signal``), by
        default the property's first."""
        signals = [s for s in raw.signals if raw_property(s) == name]
        parameter = "camera" if signals[0].kind == IMAGE else "signal"
        asked = self.get_query_argument(parameter, None)
        if asked is None or asked == "":
            return signals[0]
        for s in signals:
            if s.name == asked:
                return s
        raise tornado.web.HTTPError(400, reason=f"parameter {parameter!r}: {asked!r} is not one of {name}'s "
                                                f"{parameter}s here ({', '.join(s.name for s in signals)})")

    def max_rate(self, signal: RawSignal) -> float:
        raw = self.get_query_argument("maxRate", None)
        if raw is None or raw == "":
            return min(signal.rate_hz or DEFAULT_RATE_HZ, DEFAULT_RATE_HZ)
        try:
            rate = float(raw)
        except ValueError:
            rate = math.nan
        if not (math.isfinite(rate) and 0 < rate <= MAX_RATE_HZ):
            raise tornado.web.HTTPError(400, reason=f"parameter 'maxRate': must be a number of values per "
                                                    f"second in (0, {MAX_RATE_HZ:g}], got {raw!r}")
        return rate

    async def encoded(self, raw: RawReads, signal: RawSignal, fmt: str) -> Encoded | None:
        try:
            return await raw.read(signal.name, fmt)
        except WottHubError as e:  # the device failed to give one: the device's fault, said as such
            raise tornado.web.HTTPError(502, reason=str(e)) from None


class RawPropertyHandler(_RawBase):
    """One read of a raw signal's latest value, in the ``format`` asked (default JSON)."""

    async def get(self, thing_id: str, name: str) -> None:
        _, raw = self.raw_of(thing_id, name)
        signal = self.signal(raw, name)
        fmt = self.get_query_argument("format", "json") or "json"
        if fmt not in _FORMATS[signal.kind]:
            raise tornado.web.HTTPError(400, reason=f"parameter 'format': {fmt!r} is not one of "
                                                    f"{', '.join(_FORMATS[signal.kind])} for {name!r}")
        enc = await self.encoded(raw, signal, fmt)
        if enc is None:
            self.set_header("Retry-After", "1")
            raise tornado.web.HTTPError(503, reason=f"{name} {signal.name!r}: no frame yet")
        conn = self.request.connection
        if isinstance(conn, HTTP1Connection):  # the response's last segment at once, not after an ACK
            conn.stream.set_nodelay(True)
        self.set_header("Content-Type", enc.content_type)
        self.set_header("Cache-Control", "no-store")
        self.set_header("X-Timestamp-Ns", str(enc.t_ns))
        self.finish(enc.body)

    def put(self, thing_id: str, name: str) -> None:
        from .problem import MethodNotAllowed

        self.raw_of(thing_id, name)
        raise MethodNotAllowed("GET, OPTIONS", f"Property {name!r} of {thing_id!r} is read-only")

    def compute_etag(self) -> None:
        return None


class RawStreamHandler(_RawBase):
    """A raw signal's values as they come, at most ``maxRate`` a second, each frame at most once:
    JPEG parts of a ``multipart/x-mixed-replace`` response (images), SSE messages (grids)."""

    _closed: asyncio.Event | None = None
    _json_only = False  # the observe form: JSON values (an image as its base64 PNG) on SSE

    async def get(self, thing_id: str, name: str) -> None:
        closed = self._closed = asyncio.Event()
        thing, raw = self.raw_of(thing_id, name)
        signal = self.signal(raw, name)
        period = 1.0 / self.max_rate(signal)
        image = signal.kind == IMAGE and not self._json_only
        if self.ctx.raw_streams >= MAX_RAW_STREAMS:
            self.set_header("Retry-After", "5")
            raise tornado.web.HTTPError(503, reason=f"{MAX_RAW_STREAMS} raw-signal streams are open on this "
                                                    "hub (the most it serves at once): try again later")
        self.ctx.raw_streams += 1
        try:
            await self._stream(thing, raw, signal, period, image, closed)
        finally:
            self.ctx.raw_streams -= 1

    async def _stream(self, thing: ServedThing, raw: RawReads, signal: RawSignal, period: float, image: bool,
                      closed: asyncio.Event) -> None:
        if image:
            self.set_header("Content-Type", f"multipart/x-mixed-replace;boundary={BOUNDARY}")
        else:
            self.set_header("Content-Type", "text/event-stream; charset=utf-8")
            self.write(SSE_OPEN)
        self.set_header("Cache-Control", "no-cache, no-store")
        self.set_header("X-Accel-Buffering", "no")
        await self.flush()
        self.ctx.sse.add(self)  # ended with the others at shutdown (``end_stream``)
        last = -1
        try:
            while not closed.is_set() and self.served(thing):
                started = time.monotonic()
                enc = await self.encoded(raw, signal, "jpeg" if image else "json")
                if enc is not None and enc.t_ns != last:
                    last = enc.t_ns
                    if image:
                        self.write(b"--%b\r\nContent-Type: image/jpeg\r\nContent-Length: %d\r\n"
                                   b"X-Timestamp-Ns: %d\r\n\r\n%b\r\n"
                                   % (BOUNDARY.encode(), len(enc.body), enc.t_ns, enc.body))
                    else:
                        self.write(b"id: %d\ndata: %b\n\n" % (enc.t_ns, enc.body))
                    await self.flush()
                with contextlib.suppress(TimeoutError):  # the next frame's turn, or the end of the stream
                    await asyncio.wait_for(closed.wait(), max(0.0, period - (time.monotonic() - started)))
        except (StreamClosedError, tornado.web.HTTPError):  # the reader left, or the device failed
            pass
        finally:
            self.ctx.sse.discard(self)
        if not self._finished and not _closed(self.request):
            self.finish()

    def served(self, thing: ServedThing) -> bool:
        """Is ``thing`` still the Thing served under its id (not removed, not replaced)?"""
        return self.ctx.things.get(thing.id) is thing

    def heartbeat(self, now: float, every_s: float) -> None:
        """Streams write at their own rate (``ServingContext`` beats SSE streams; nothing to add here)."""

    def end_stream(self) -> None:
        if self._closed is not None:
            self._closed.set()

    def on_connection_close(self) -> None:
        self.end_stream()


class RawObserveHandler(RawStreamHandler):
    """``.../observe``: an SSE stream of JSON values (``Accept: text/event-stream``), else one long-poll
    answer: the first frame newer than the one there when asked (within ``LONG_POLL_S``, else the latest)."""

    _json_only = True

    async def get(self, thing_id: str, name: str) -> None:
        if "text/event-stream" in self.request.headers.get("Accept", ""):
            await super().get(thing_id, name)
            return
        closed = self._closed = asyncio.Event()
        thing, raw = self.raw_of(thing_id, name)
        signal = self.signal(raw, name)
        period = 1.0 / max(signal.rate_hz or DEFAULT_RATE_HZ, DEFAULT_RATE_HZ)
        first = await self.encoded(raw, signal, "json")
        enc = first
        deadline = time.monotonic() + LONG_POLL_S
        self.ctx.sse.add(self)
        try:
            while (enc is None or (first is not None and enc.t_ns == first.t_ns)) \
                    and time.monotonic() < deadline and not closed.is_set() and self.served(thing):
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(closed.wait(), period)
                enc = await self.encoded(raw, signal, "json")
        finally:
            self.ctx.sse.discard(self)
        if _closed(self.request):
            return
        if not self.served(thing):
            raise tornado.web.HTTPError(404, reason=f"Thing {thing_id!r} was removed")
        if enc is None:
            self.set_header("Retry-After", "1")
            raise tornado.web.HTTPError(503, reason=f"{name} {signal.name!r}: no frame yet")
        self.set_header("Content-Type", enc.content_type)
        self.set_header("Cache-Control", "no-store")
        self.set_header("X-Timestamp-Ns", str(enc.t_ns))
        self.finish(enc.body)


def _closed(request: HTTPServerRequest) -> bool:
    """Has the client gone (tornado's HTTPServer serves every request over an HTTP1Connection)?"""
    conn = request.connection
    return not isinstance(conn, HTTP1Connection) or conn.stream.closed()
