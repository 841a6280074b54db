"""The WoT Discovery HTTP API on tornado: routes, authorisation, bodies, problem details.

``directory_handlers(directory, prefix)`` returns plain tornado routes so a hub
can mount the directory in its own Application (same IOLoop); ``make_app``
wraps them in an Application of their own for the standalone command.

Every answer carries ``Access-Control-Allow-Origin: *`` like the hub's other
routes, every route answers ``OPTIONS`` (a CORS preflight: 204 with the methods
it allows, never behind the token, which preflights do not carry), and unknown
paths under the directory's prefixes answer a problem+json 404. Writes from
HTTP clients are ``remote`` writes: the directory refuses them (403) on the TDs
its embedder holds (``Directory`` docstring).
"""

from __future__ import annotations

import asyncio
import hmac
import json
import logging
from typing import Any
from urllib.parse import quote, urlencode

from tornado.iostream import StreamClosedError
from tornado.log import access_log, app_log, gen_log
from tornado.web import Application, HTTPError, RequestHandler, stream_request_body

from .directory import Directory
from .errors import (
    PROBLEM_CONTENT_TYPE,
    BadRequest,
    DirectoryError,
    Forbidden,
    NotFound,
    PayloadTooLarge,
    Unauthorized,
    UnsupportedMediaType,
    problem_body,
)
from .events import EVENT_TYPES
from .registration import DISCOVERY_CONTEXT
from .settings import DirectorySettings, is_loopback

__all__ = ["directory_handlers", "log_request", "make_app"]

log = logging.getLogger("wott_directory.http")

TD_TYPE = "application/td+json"
LD_TYPE = "application/ld+json"
JSON_TYPE = "application/json"
TEXT_TYPE = "text/plain"
"""What the directory's TD declares for the empty bodies of 201 and 204 answers (selftd.py)."""
SSE_RETRY_MS = 1000
"""Every event stream starts with this ``retry:`` line, at once: a field, not a comment line (some older
clients took one for an empty message and lost the first), and without a blank line after it (it
belongs to the first event: httpx-sse dispatches any block holding a ``retry:``, empty or not). An
``EventSource`` reconnects after that long, with ``Last-Event-ID``."""
TD_INPUT_TYPES = {TD_TYPE, JSON_TYPE, LD_TYPE}
MERGE_PATCH_TYPE = "application/merge-patch+json"


def _dumps(doc: Any) -> bytes:
    return json.dumps(doc, ensure_ascii=False, separators=(",", ":")).encode("utf-8")


_ALLOW_HEADERS = "Authorization, Content-Type, Accept, Last-Event-ID"
_EXPOSE_HEADERS = "Location, Link, ETag, Retry-After, WWW-Authenticate"


class BaseHandler(RequestHandler):
    directory: Directory
    methods = "GET, HEAD, OPTIONS"
    """What ``OPTIONS`` announces (``Allow`` and ``Access-Control-Allow-Methods``)."""

    def initialize(self, directory: Directory) -> None:
        self.directory = directory

    def set_default_headers(self) -> None:
        self.set_header("Access-Control-Allow-Origin", "*")
        self.set_header("Access-Control-Expose-Headers", _EXPOSE_HEADERS)

    def options(self, *_args: Any) -> None:
        self.set_status(204)
        self.set_header("Allow", self.methods)
        self.set_header("Access-Control-Allow-Methods", self.methods)
        self.set_header("Access-Control-Allow-Headers", _ALLOW_HEADERS)
        self.set_header("Access-Control-Max-Age", "600")
        self.finish()

    @property
    def conf(self) -> DirectorySettings:
        """The directory's settings (tornado's ``self.settings`` are the Application's)."""
        return self.directory.settings

    def authorize(self, write: bool) -> None:
        """Writes need the token (or an open directory and a loopback client); reads only if protected."""
        s = self.conf
        if not write and not s.protect_reads:
            return
        if write and s.open_writes and is_loopback(self.request.remote_ip or ""):
            return
        if s.token is None:
            raise Forbidden("This directory accepts no writes: it has no token configured")
        header = self.request.headers.get("Authorization", "")
        scheme, _, credential = header.partition(" ")
        if scheme.lower() != "bearer" or not credential.strip():
            what = "Writing to" if write else "Reading"
            raise Unauthorized(f"{what} this directory needs 'Authorization: Bearer <token>'")
        if not hmac.compare_digest(credential.strip().encode(), s.token.encode()):
            raise Unauthorized("The bearer token is not valid", error="invalid_token")

    def write_json(self, doc: Any, content_type: str, status: int = 200) -> None:
        self.set_status(status)
        self.set_header("Content-Type", content_type)
        self.finish(_dumps(doc))

    _keep_content_type = False

    def finish_empty(self, status: int) -> None:
        """A 201 or 204 with no body, as the TD's ``response`` declares it: ``text/plain`` (not
        tornado's default ``text/html``, or no type at all on a 204). node-wot 0.9.2 checks an
        action's answer against the declared type and throws, after the write succeeded, on any
        other; with no Content-Type it assumes application/json."""
        self.set_status(status)
        self.set_header("Content-Type", TEXT_TYPE)
        self._keep_content_type = True
        self.finish()

    def _clear_representation_headers(self) -> None:
        # tornado drops Content-Type from a 204 (and 304); finish_empty's answer keeps it
        if self._keep_content_type:
            self.clear_header("Content-Encoding")
            self.clear_header("Content-Language")
        else:
            super()._clear_representation_headers()

    def write_error(self, status_code: int, **kwargs: Any) -> None:
        exc = kwargs.get("exc_info", (None, None, None))[1]
        if isinstance(exc, DirectoryError):
            error = exc
        elif isinstance(exc, HTTPError):
            error = DirectoryError(exc.status_code, exc.log_message or self._reason)
        else:
            error = DirectoryError(status_code, "Internal error" if status_code >= 500 else self._reason)
        self.set_status(error.status)
        for name, value in error.headers.items():
            self.set_header(name, value)
        self.set_header("Content-Type", PROBLEM_CONTENT_TYPE)
        self.clear_header("Link")
        self.finish(problem_body(error.problem(instance=self.request.path)))

    def send_error(self, status_code: int = 500, **kwargs: Any) -> None:
        exc = kwargs.get("exc_info", (None, None, None))[1]
        if isinstance(exc, DirectoryError):
            status_code = exc.status
        super().send_error(status_code, **kwargs)

    def log_exception(self, typ: Any, value: Any, tb: Any) -> None:
        """Log lines name the path, never the query: a client may pass its token as
        ``?access_token=`` (tornado's own lines quote the whole URI)."""
        method, path = self.request.method, self.request.path
        if isinstance(value, DirectoryError):
            log.info("%s %s -> %s", method, path, value)
        elif isinstance(value, HTTPError):
            if value.log_message:
                gen_log.warning("%d %s %s (%s): %s", value.status_code, method, path, self.request.remote_ip,
                                value.log_message % value.args if value.args else value.log_message)
        else:
            app_log.error("Uncaught exception %s %s (%s)", method, path, self.request.remote_ip,
                          exc_info=(typ, value, tb))


class NotFoundHandler(BaseHandler):
    def prepare(self) -> None:
        raise NotFound(f"No resource at {self.request.path}")


def _preflight(handler: RequestHandler) -> bool:
    return handler.request.method == "OPTIONS"


def _media_type(value: str | None) -> str | None:
    return value.split(";", 1)[0].strip().lower() if value else None


@stream_request_body
class _BodyHandler(BaseHandler):
    """Reads the body itself so an oversized one is answered with 413, not a dropped connection
    (tornado's own ``max_body_size`` closes the connection without a response)."""

    _bad_path: DirectoryError | None = None

    def decode_argument(self, value: bytes, name: str | None = None) -> str:
        """A path that is not UTF-8 is refused like the rest: after the body is read (tornado's own
        400 comes before, and the client sending a body sees a reset connection)."""
        try:
            return super().decode_argument(value, name)
        except HTTPError:
            if name is not None:  # a query argument, decoded while handling: answered normally
                raise
            self._bad_path = BadRequest(f"The path is not valid UTF-8: {value[:80]!r}")
            return value.decode("latin-1")

    def prepare(self) -> None:
        self._chunks: list[bytes] = []
        self._size = 0
        self._too_big = False
        self._refused: DirectoryError | None = self._bad_path
        if _preflight(self):  # a CORS preflight never carries the token
            return
        if self.request.method in ("PUT", "POST", "PATCH", "DELETE"):
            # Refusals are answered once the body is read (and dropped): a response sent while
            # the client is still sending is lost to a connection reset.
            try:
                self.authorize(write=True)
            except DirectoryError as e:
                self._refused = e  # not authorised comes before a bad path
            length = self.request.headers.get("Content-Length")
            self._too_big = bool(length and length.isdigit() and int(length) > self.conf.max_body_bytes)
        else:
            # never raise here: tornado drops the connection of a streamed request that is
            # answered before it was read, and the client's next request on it fails
            try:
                self.authorize(write=False)
            except DirectoryError as e:
                self._refused = e

    def data_received(self, chunk: bytes) -> None:
        self._size += len(chunk)
        if self._refused is not None:
            return
        if self._size > self.conf.max_body_bytes:
            self._too_big = True
            self._chunks = []
        elif not self._too_big:
            self._chunks.append(chunk)

    def check_refused(self) -> None:
        if self._refused is not None:
            raise self._refused

    async def json_body(self, allowed: set[str], required: bool) -> Any:
        self.check_refused()
        if self._too_big:
            raise PayloadTooLarge(self.conf.max_body_bytes)
        media = _media_type(self.request.headers.get("Content-Type"))
        if media is None and required:
            raise UnsupportedMediaType(f"Content-Type must be {' or '.join(sorted(allowed))}")
        if media is not None and media not in allowed:
            raise UnsupportedMediaType(f"Content-Type {media} is not accepted here; use "
                                       f"{' or '.join(sorted(allowed))}")
        return await self.directory.parse_body(b"".join(self._chunks))


class ThingsHandler(_BodyHandler):
    """``/things``: listing (GET/HEAD) and anonymous creation (POST)."""

    methods = "GET, HEAD, POST, OPTIONS"

    def _int_arg(self, name: str, minimum: int) -> int | None:
        raw = self.get_query_argument(name, None)
        if raw is None:
            return None
        try:
            value = int(raw)
        except ValueError:
            raise BadRequest(f"Query argument {name} must be an integer, not {raw!r}") from None
        if value < minimum:
            raise BadRequest(f"Query argument {name} must be at least {minimum}, not {value}")
        return value

    def get(self) -> None:
        self.check_refused()
        s = self.conf
        offset = self._int_arg("offset", 0) or 0
        limit = self._int_arg("limit", 1)
        fmt = self.get_query_argument("format", "array")
        if fmt not in ("array", "collection"):
            raise BadRequest(f"Query argument format must be 'array' or 'collection', not {fmt!r}")
        items, total = self.directory.page(offset, min(limit or s.page_size, s.page_size))
        base = s.base_url
        next_url = None
        if offset + len(items) < total:
            params: dict[str, Any] = {"offset": offset + len(items)}
            if limit is not None:
                params["limit"] = limit
            if fmt != "array":
                params["format"] = fmt
            next_url = f"{base}things?{urlencode(params)}"
            self.add_header("Link", f'<{next_url}>; rel="next"')
        self.add_header("Link", f'<{base}things>; rel="canonical"; etag="{self.directory.etag}"')
        if fmt == "array":
            self.write_json(items, LD_TYPE)
            return
        query = self.request.query
        body: dict[str, Any] = {
            "@context": DISCOVERY_CONTEXT, "@type": "ThingCollection",
            "@id": f"{base}things" + (f"?{query}" if query else ""), "members": items, "total": total,
        }
        if next_url:
            body["next"] = next_url
        self.write_json(body, LD_TYPE)

    head = get

    async def post(self) -> None:
        td = await self.json_body(TD_INPUT_TYPES, required=False)
        thing_id = await self.directory.create_anonymous(td, remote=True)
        self.set_header("Location", f"{self.conf.base_url}things/{quote(thing_id, safe=':')}")
        self.finish_empty(201)


class ThingHandler(_BodyHandler):
    """``/things/{id}``: retrieve, create/replace, merge-patch, delete one TD."""

    methods = "GET, HEAD, PUT, PATCH, DELETE, OPTIONS"

    def get(self, thing_id: str) -> None:
        self.check_refused()
        self.write_json(self.directory.get(thing_id), TD_TYPE)

    head = get

    async def put(self, thing_id: str) -> None:
        td = await self.json_body(TD_INPUT_TYPES, required=False)
        created = await self.directory.put(thing_id, td, remote=True)
        self.finish_empty(201 if created else 204)

    async def patch(self, thing_id: str) -> None:
        patch = await self.json_body({MERGE_PATCH_TYPE}, required=True)
        await self.directory.patch(thing_id, patch, remote=True)
        self.finish_empty(204)

    async def delete(self, thing_id: str) -> None:
        self.check_refused()
        await self.directory.delete(thing_id, remote=True)
        self.finish_empty(204)


class JSONPathHandler(BaseHandler):
    def prepare(self) -> None:
        if not _preflight(self):
            self.authorize(write=False)

    async def get(self) -> None:
        query = self.get_query_argument("query", None, strip=False)
        if not query:
            raise BadRequest("The query argument (an RFC 9535 JSONPath expression) is required")
        body = await self.directory.search_json(query, _dumps)
        self.set_header("Content-Type", JSON_TYPE)
        self.finish(body)

    head = get


class UnsupportedSearchHandler(BaseHandler):
    def prepare(self) -> None:
        kind = self.path_args[0] if self.path_args else "this"
        raise DirectoryError(501, f"{kind} search is not implemented by this directory; "
                                  "use /search/jsonpath (RFC 9535)")


class WellKnownHandler(BaseHandler):
    """``/.well-known/wot``: the directory's own TD, always readable (it is how clients find us)."""

    def get(self) -> None:
        self.write_json(self.directory.own_td(), TD_TYPE)

    head = get


_KEEPALIVE = object()


class EventsHandler(BaseHandler):
    """``/events`` and ``/events/{type}``: Server-Sent Events with ``diff`` and ``Last-Event-ID``."""

    _sub = None
    _keepalive: asyncio.TimerHandle

    def prepare(self) -> None:
        if not _preflight(self):
            self.authorize(write=False)

    def _types(self, kind: str | None) -> tuple[str, ...]:
        if kind is None:
            return EVENT_TYPES
        if kind not in EVENT_TYPES:
            raise NotFound(f"No event type {kind!r}; the types are {', '.join(EVENT_TYPES)}")
        return (kind,)

    def _diff(self) -> bool:
        raw = self.get_query_argument("diff", "false").lower()
        if raw not in ("true", "false", "1", "0"):
            raise BadRequest(f"Query argument diff must be true or false, not {raw!r}")
        return raw in ("true", "1")

    def _last_event_id(self) -> int | None:
        raw = self.request.headers.get("Last-Event-ID")
        if raw is None or not raw.strip():
            return None
        try:
            return int(raw.strip())
        except ValueError:
            raise BadRequest(f"Last-Event-ID {raw!r} is not an id this directory gave") from None

    def _stream_headers(self) -> None:
        self.set_header("Content-Type", "text/event-stream")
        self.set_header("Cache-Control", "no-cache")
        self.set_header("X-Accel-Buffering", "no")

    def head(self, kind: str | None = None) -> None:
        self._types(kind)
        self._diff()
        self._last_event_id()
        self._stream_headers()
        self.finish()

    async def get(self, kind: str | None = None) -> None:
        types = self._types(kind)
        diff = self._diff()
        last = self._last_event_id()
        self._stream_headers()
        hub = self.directory.events
        sub, missed = hub.subscribe(types, diff, last)
        self._sub = sub
        self._keepalive = asyncio.get_running_loop().call_later(self.conf.sse_keepalive, self._ping)
        try:
            self.write(f"retry: {SSE_RETRY_MS}\n".encode())
            for old in missed:
                self.write(old.sse(diff))
            await self.flush()
            while not (sub.closed or sub.overflowed):
                ev = await sub.queue.get()
                while ev is not None:
                    if ev is _KEEPALIVE:
                        self.write(b":\n\n")
                    else:
                        self.write(ev.sse(diff))
                    ev = sub.queue.get_nowait() if not sub.queue.empty() else None
                if sub.closed or sub.overflowed:
                    break
                await self.flush()
        except StreamClosedError:
            pass
        finally:
            self._keepalive.cancel()
            hub.unsubscribe(sub)
        if not self._finished:
            try:
                self.finish()
            except StreamClosedError:
                pass

    def _ping(self) -> None:
        sub = self._sub
        if sub is None or sub.closed:
            return
        if sub.queue.empty():
            sub.queue.put_nowait(_KEEPALIVE)  # type: ignore[arg-type]  # a sentinel, told apart by identity
        self._keepalive = asyncio.get_running_loop().call_later(self.conf.sse_keepalive, self._ping)

    def on_connection_close(self) -> None:
        if self._sub is not None:
            self._sub.close()


def directory_handlers(directory: Directory, prefix: str = "",
                       well_known: bool = True) -> list[tuple[Any, ...]]:
    """Tornado routes of the directory API under ``prefix`` (e.g. ``/tdd``); mount them in any
    Application. ``well_known`` adds ``/.well-known/wot`` (always at the host's root)."""
    p = prefix.rstrip("/")
    kw = {"directory": directory}
    routes: list[tuple[Any, ...]] = [
        (rf"{p}/things", ThingsHandler, kw),
        (rf"{p}/things/(.+)", ThingHandler, kw),
        (rf"{p}/search/jsonpath", JSONPathHandler, kw),
        (rf"{p}/search/(xpath|sparql)", UnsupportedSearchHandler, kw),
        (rf"{p}/events", EventsHandler, kw),
        (rf"{p}/events/([^/]+)", EventsHandler, kw),
    ]
    if well_known:
        routes.append((r"/\.well-known/wot", WellKnownHandler, kw))
    # the rest of the directory's paths (``/things/``, ``/search/other``, ``/events/a/b``): a problem
    # here, not the embedding application's (HTML) default
    routes.append((rf"{p}/(?:things|search|events)(?:/.*)?", NotFoundHandler, kw))
    return routes


def log_request(handler: RequestHandler) -> None:
    """tornado's access log line with the path, not the URI: the query may hold ``access_token``."""
    status = handler.get_status()
    write = access_log.info if status < 400 else access_log.warning if status < 500 else access_log.error
    req = handler.request
    write("%d %s %s (%s) %.2fms", status, req.method, req.path, req.remote_ip, 1000.0 * req.request_time())


def make_app(directory: Directory, prefix: str = "", **tornado_settings: Any) -> Application:
    """A tornado Application serving only the directory (unknown paths answer problem+json 404)."""
    tornado_settings.setdefault("log_function", log_request)
    return Application(directory_handlers(directory, prefix), default_handler_class=NotFoundHandler,
                       default_handler_args={"directory": directory}, **tornado_settings)
