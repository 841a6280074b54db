"""wotpy's WebSocket JSON-RPC binding, without the per-message jsonschema cost.

wotpy's ``WebsocketHandler`` validates every incoming request, every outgoing
response and every emitted event against JSON Schemas (``jsonschema.validate``
re-checks the schema itself each time) and routes events through reactivex
filters that every subscription evaluates for every event of the Thing: a few
hundred events/s saturate it. This handler speaks the same protocol (same
methods, messages, subscription ids and error codes, so wotpy's
``WebsocketClient`` works unchanged) with:

- requests checked by the same rules as wotpy's ``SCHEMA_REQUEST`` and params
  schemas, written as plain Python checks;
- outgoing messages built by string concatenation from the record's JSON text
  (encoded once for every consumer), so no re-encoding and no validation of
  what the hub itself produced;
- subscriptions served by the event plane (only the matching records reach a
  subscription; a subscription that falls ``max_pending`` behind means the
  client stopped reading its socket: the connection is closed at once, its
  buffers let go (issue 48: an error message queued behind the backlog pinned
  it all), and the client reconnects as after any drop);
- property reads answered from the encoded values of the served Thing;
- the messages of a batch framed here and written to the socket in one write
  (tornado's ``write_message`` creates a task and makes a ``send`` call per
  message: ~7k messages/s). Framing is RFC 6455 for a server (unmasked, FIN,
  text opcode); it is used only when no compression was negotiated (this
  handler never offers it), otherwise ``write_message`` is used.

Things not served by the hub (produced directly on the servient) fall back to
wotpy's own handlers.

Removal ends every stream, as on SSE: when the Thing is no longer served (``removeDevice``),
each of its subscriptions gets an end message (a ``SUBSCRIPTION_ERROR`` with
``data: {"subscription": id, "ended": "removed"}``: wotpy's client hands it to the
subscriber's ``on_error``) and the socket is closed with 1001 (going away).

Bad input never costs the connection: a message that does not parse (nested
too deep for the decoder included) gets a JSON-RPC error reply, and any failure
while handling one is answered ``INTERNAL_ERROR`` and logged; a URL naming no
Thing is refused at the handshake with a problem+json 404. One connection holds
at most ``MAX_SUBSCRIPTIONS`` subscriptions (hub and wotpy ones together): each
costs a pump task and an event-plane subscriber, and an unbounded number on one
socket slows every client of the hub. Beyond it a subscribe request gets an
``INVALID_REQUEST`` error naming the limit; disposing one frees a place.
"""

from __future__ import annotations

import asyncio
import json
import logging
import struct
import time
import uuid
from typing import Any

import tornado.web
from tornado.iostream import StreamClosedError
from tornado.websocket import WebSocketClosedError
from wotpy.protocols.ws.enums import WebsocketErrors, WebsocketMethods
from wotpy.protocols.ws.handler import WebsocketHandler
from wotpy.protocols.ws.messages import WebsocketMessageRequest

from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY, Record
from wott_hub.events.subscriber import Subscriber
from wott_hub.security.policy import allows
from wott_hub.security.scopes import Scope

from .context import ServingContext
from .problem import write_problem
from .sending import send_now
from .things import ServedThing

__all__ = ["MAX_SUBSCRIPTIONS", "FastWebsocketHandler"]

MAX_SUBSCRIPTIONS = 256
"""Subscriptions one WebSocket connection may hold at once (a client needing more opens another)."""

log = logging.getLogger(__name__)
_SUBSCRIBE = frozenset({WebsocketMethods.ON_EVENT, WebsocketMethods.ON_PROPERTY_CHANGE,
                        WebsocketMethods.ON_TD_CHANGE})

_METHODS = frozenset(WebsocketMethods.list())
_NEEDS_NAME = frozenset({WebsocketMethods.READ_PROPERTY, WebsocketMethods.WRITE_PROPERTY,
                         WebsocketMethods.INVOKE_ACTION, WebsocketMethods.ON_PROPERTY_CHANGE,
                         WebsocketMethods.ON_EVENT})
_dumps = json.dumps
_CONTROL = frozenset({WebsocketMethods.WRITE_PROPERTY, WebsocketMethods.INVOKE_ACTION})


class _Invalid(Exception):
    def __init__(self, message: str, code: int, msg_id: Any = None) -> None:
        super().__init__(message)
        self.code = code
        self.msg_id = msg_id


def _parse_request(raw: str | bytes) -> tuple[str, Any, Any]:
    """(method, params, id), by the rules of wotpy's SCHEMA_REQUEST and SCHEMA_PARAMS_*."""
    try:
        msg = json.loads(raw)
    except (ValueError, TypeError) as e:
        raise _Invalid(f"Parse error: {e}", WebsocketErrors.PARSE_ERROR) from None
    except RecursionError:
        raise _Invalid("Parse error: nested too deeply", WebsocketErrors.PARSE_ERROR) from None
    if not isinstance(msg, dict):
        raise _Invalid("Invalid request: not an object", WebsocketErrors.INVALID_REQUEST)
    msg_id = msg.get("id")
    if msg.get("jsonrpc") != "2.0":
        raise _Invalid("Invalid request: 'jsonrpc' must be '2.0'", WebsocketErrors.INVALID_REQUEST)
    method = msg.get("method")
    if not isinstance(method, str) or method not in _METHODS:
        raise _Invalid(f"Invalid request: unknown method {method!r}", WebsocketErrors.INVALID_REQUEST)
    if "params" not in msg or not isinstance(msg["params"], dict | list):
        raise _Invalid("Invalid request: 'params' must be an object or array",
                       WebsocketErrors.INVALID_REQUEST)
    if msg_id is not None and (isinstance(msg_id, bool) or not isinstance(msg_id, str | int)):
        raise _Invalid("Invalid request: 'id' must be a string, an integer or null",
                       WebsocketErrors.INVALID_REQUEST)
    params = msg["params"]
    if method in _NEEDS_NAME and not (isinstance(params, dict) and isinstance(params.get("name"), str)):
        raise _Invalid("Invalid params: 'name' (string) is required", WebsocketErrors.INVALID_METHOD_PARAMS,
                       msg_id)
    if method == WebsocketMethods.WRITE_PROPERTY and "value" not in params:
        raise _Invalid("Invalid params: 'value' is required", WebsocketErrors.INVALID_METHOD_PARAMS, msg_id)
    if method == WebsocketMethods.DISPOSE and not (isinstance(params, dict)
                                                   and isinstance(params.get("subscription"), str)):
        raise _Invalid("Invalid params: 'subscription' (string) is required",
                       WebsocketErrors.INVALID_METHOD_PARAMS, msg_id)
    return method, params, msg_id


def _text_frame(payload: bytes) -> bytes:
    """One unmasked, final text frame (RFC 6455 section 5.2), as a server sends it."""
    n = len(payload)
    if n < 126:
        return struct.pack("!BB", 0x81, n) + payload
    if n <= 0xFFFF:
        return struct.pack("!BBH", 0x81, 126, n) + payload
    return struct.pack("!BBQ", 0x81, 127, n) + payload


def _response(result_json: str, msg_id: Any) -> str:
    return '{"jsonrpc":"2.0","result":' + result_json + ',"id":' + _dumps(msg_id) + "}"


def _error(message: str, code: int, msg_id: Any = None, data: Any = None) -> str:
    return _dumps({"jsonrpc": "2.0", "error": {"code": code, "message": message, "data": data},
                   "id": msg_id})


class FastWebsocketHandler(WebsocketHandler):
    def initialize(self, ctx: ServingContext) -> None:
        self.ctx = ctx
        # subscription id -> event-plane Subscriber (None until the hub's streams are ready)
        self._hub_subs: dict[str, Subscriber | None] = {}
        self._wotpy_pending: set[asyncio.Future[Any]] = set()  # wotpy subscribe requests not yet run
        self._served: ServedThing | None = None

    def prepare(self) -> None:
        """Refuse the handshake for a URL that names no Thing (wotpy would accept, then fail)."""
        name = self.path_kwargs.get("name", "")
        if name not in self.ctx.things.by_ws_name:
            try:
                self._server.get_exposed_thing(name)
            except ValueError:
                raise tornado.web.HTTPError(404, reason=f"Unknown Thing {name!r}") from None

    def write_error(self, status_code: int, **kwargs: Any) -> None:
        write_problem(self, status_code, **kwargs)

    def open(self, name: str) -> None:
        super().open(name)
        self.set_nodelay(True)  # events are small: Nagle + delayed ACK would hold them up to 40 ms
        self._served = self.ctx.things.by_ws_name.get(name)
        self.ctx.ws.add(self)

    def _send(self, text: str) -> None:
        try:
            self.write_message(text)
        except WebSocketClosedError:
            pass

    async def on_message(self, message: str | bytes) -> None:
        try:
            method, params, msg_id = _parse_request(message)
        except _Invalid as e:
            self._send(_error(str(e), e.code, e.msg_id))
            return
        if method in _SUBSCRIBE and self.subscription_count >= MAX_SUBSCRIPTIONS:
            self._send(_error(f"Invalid request: this connection already holds {MAX_SUBSCRIPTIONS} "
                              "subscriptions (the maximum); dispose one first",
                              WebsocketErrors.INVALID_REQUEST, msg_id,
                              {"maxSubscriptions": MAX_SUBSCRIPTIONS}))
            return
        if method in _CONTROL and not allows(self.request, Scope.CONTROL):  # scope of the handshake's token
            self._send(_error(f"Forbidden: {method} needs a token with scope control",
                              WebsocketErrors.INVALID_REQUEST, msg_id))
            return
        try:
            self._dispatch(method, params, msg_id)
        except Exception as e:  # a bug here must cost one reply, not the connection
            log.exception("WebSocket request %s failed", method)
            self._send(_error(f"Internal error: {type(e).__name__}", WebsocketErrors.INTERNAL_ERROR, msg_id))

    @property
    def subscription_count(self) -> int:
        """Subscriptions this connection holds: the hub's (pending ones too) and wotpy's."""
        return len(self._hub_subs) + len(self._subscriptions) + len(self._wotpy_pending)

    def _dispatch(self, method: str, params: Any, msg_id: Any) -> None:
        served = self._served
        if served is None:  # a Thing produced directly on the servient: wotpy's own path
            self._to_wotpy(method, params, msg_id)
            return
        if method == WebsocketMethods.READ_PROPERTY:
            value = served.read(params["name"])
            if value is None:
                self._send(_error(f"Unknown property: {params['name']}", WebsocketErrors.INTERNAL_ERROR,
                                  msg_id))
            else:
                self._send(_response(value, msg_id))
        elif method == WebsocketMethods.ON_EVENT:
            name = params["name"]
            if name not in (served.td.get("events") or {}):
                self._send(_error("Unknown event", WebsocketErrors.INTERNAL_ERROR, msg_id))
                return
            self._subscribe(served.id, (KIND_EVENT, name), msg_id)
        elif method == WebsocketMethods.ON_PROPERTY_CHANGE:
            name = params["name"]
            if name not in (served.td.get("properties") or {}):
                self._send(_error("Unknown property", WebsocketErrors.INTERNAL_ERROR, msg_id))
            elif not served.is_observable(name):
                self._send(_error("Property is not observable", WebsocketErrors.INTERNAL_ERROR, msg_id))
            else:
                self._subscribe(served.id, (KIND_PROPERTY, name), msg_id)
        elif method == WebsocketMethods.DISPOSE:
            sid = params["subscription"]
            if sid in self._hub_subs:
                sub = self._hub_subs.pop(sid)
                if sub is not None:  # None: still waiting for the streams; its pump sees it is gone
                    sub.close()
                self._send(_response(_dumps(sid), msg_id))
            elif sid in self._subscriptions:
                self._dispose_subscription(sid)
                self._send(_response(_dumps(sid), msg_id))
            else:
                self._send(_response("null", msg_id))
        else:  # write_property, invoke_action, on_td_change: wotpy's semantics (rare, not hot)
            self._to_wotpy(method, params, msg_id)

    def _to_wotpy(self, method: str, params: Any, msg_id: Any) -> None:
        """Hand a request to wotpy's handler; a subscription is counted at once, so the cap holds."""
        req = WebsocketMessageRequest(method=method, params=params, msg_id=msg_id)
        task = asyncio.ensure_future(self._handle(req))
        if method in _SUBSCRIBE:
            self._wotpy_pending.add(task)
            task.add_done_callback(self._wotpy_pending.discard)

    def _subscribe(self, thing: str, interest: tuple[int, str], msg_id: Any) -> None:
        sid = str(uuid.uuid4())
        self._send(_response(_dumps(sid), msg_id))
        sub = self.ctx.plane.subscribe(thing, interest) if self.ctx.streams_ready.is_set() else None
        self._hub_subs[sid] = sub
        asyncio.ensure_future(self._pump(sid, sub, thing, interest))

    async def _pump(self, sid: str, sub: Subscriber | None, thing: str, interest: tuple[int, str]) -> None:
        if sub is None:  # the hub is still opening its history: subscribe once streams are ready
            await self.ctx.streams_ready.wait()
            if sid not in self._hub_subs or self.ws_connection is None:  # disposed or closed meanwhile
                return
            sub = self.ctx.plane.subscribe(thing, interest)
            self._hub_subs[sid] = sub
        conn = self.ws_connection
        if conn is not None and conn.stream is not None:
            sub.cut = conn.stream.close  # cut off at max_pending: the connection closed, its buffers let go
        kind, name = interest
        if kind == KIND_EVENT:
            head = '{"subscription":"' + sid + '","name":' + _dumps(name) + ',"data":'
            tail = "}"
        else:  # wotpy's PropertyChangeEmittedEvent: name "propertychange", data {name, value}
            head = ('{"subscription":"' + sid + '","name":"propertychange","data":{"name":'
                    + _dumps(name) + ',"value":')
            tail = "}}"

        def frame(rec: Record) -> bytes:
            return _text_frame((head + rec.data + tail).encode())

        def direct(rec: Record) -> bool:  # push writes a record itself while the socket keeps up
            conn = self.ws_connection
            if conn is None or getattr(conn, "_compressor", None) is not None:
                return False
            stream = conn.stream
            if stream.writing() or stream.closed():
                return False
            send_now(stream, frame(rec))
            if rec.trace is not None:
                rec.trace["ws"] = time.perf_counter_ns()
            return True

        try:
            async for batch in sub.batches(direct):
                conn = self.ws_connection
                if conn is None:
                    break
                if batch[0].trace is not None:  # benchmarks: when the batch goes to the socket
                    t = time.perf_counter_ns()
                    for r in batch:
                        if r.trace is not None:  # the whole batch is traced or none of it
                            r.trace["ws"] = t
                if getattr(conn, "_compressor", None) is None:
                    sent = send_now(conn.stream, b"".join([frame(r) for r in batch]))
                    if sent is not None:  # back-pressure: wait only while the socket is backed up
                        await sent  # (not per batch: a future wake-up per record, as for SSE)
                else:
                    for r in batch:
                        fut = self.write_message(head + r.data + tail)
                    await fut  # back-pressure: the next batch waits for the socket
        except (WebSocketClosedError, StreamClosedError):
            pass
        finally:
            sub.close()
            ours = self._hub_subs.pop(sid, None) is not None  # not disposed by the client
        if sub.overflowed:
            pass  # the connection was closed (``sub.cut``): nothing more can reach this client
        elif ours and self.ws_connection is not None and thing not in self.ctx.things.by_id:
            self._ended(sid, thing)

    def _ended(self, sid: str, thing: str) -> None:
        """The Thing was removed (``removeDevice``): the subscription's end message (a subscription
        error naming it, which wotpy's client passes to the subscriber's ``on_error``, as an SSE stream
        ends), then, once no subscription is left, the socket is closed (1001: the Thing went away)."""
        self._send(_error(f"Thing {thing!r} was removed: subscription ended",
                          WebsocketErrors.SUBSCRIPTION_ERROR, data={"subscription": sid, "ended": "removed"}))
        if not self._hub_subs and self.ws_connection is not None:
            self.close(1001, f"Thing {thing!r} was removed")

    def on_close(self) -> None:
        for sub in list(self._hub_subs.values()):
            if sub is not None:
                sub.close()
        self._hub_subs.clear()
        self.ctx.ws.discard(self)
        super().on_close()
