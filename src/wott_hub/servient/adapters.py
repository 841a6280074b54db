"""Small adapters that make wotpy 0.18 fast with hundreds of Things on one servient.

Each one replaces a wotpy method whose cost grows with the fleet by one with the
same contract and a constant cost; docs/wotpy-adapters.md lists them with the
wotpy limit, what changes and why it is safe. Nothing in site-packages is edited.

- ``FastThing``: wotpy's ``Thing.title``/``id`` rebuild the whole ThingFragment
  (every interaction's data schema through ``WotBaseDict.to_dict``, which calls
  ``dir()`` per field) on every access; lookups by title call them for every
  Thing. Here they are read once from the fragment (they are read-only in wotpy).
- ``IndexedExposedThingSet``: wotpy scans all Things for every lookup (by title,
  URL name, interaction); here dictionaries answer in O(1), same semantics.
- ``HubServient``: wotpy's ``enable_exposed_thing`` regenerates the forms of
  every Thing on every server, so exposing N Things costs O(N²) form builds.
  The hub serves its own TDs (built by ``wott_hub.td.builder`` with the hub's
  forms), so wotpy's internal forms are not generated (``create_default_forms``
  off) and enabling a Thing only registers it with the servers.
- ``HubHTTPServer`` / ``HubWebsocketServer``: bind to the configured address
  (wotpy listens on all interfaces) before the servient starts, so port 0 works
  and the forms carry the real port; the HTTP server's tornado Application is
  built from an extendable list of handlers, so SSE, TD, context and later the
  directory share one port with wotpy's own routes.
- ``WOTPY_ROUTE_HANDLERS``: wotpy's HTTP route handlers answer an unknown Thing,
  property, action or event with a 500 (``HTTPError`` without a status, a
  ``KeyError``), a non-JSON body with a 500, OPTIONS with a 500-free 405 but no
  CORS, and a PUT to a read-only property never at all (``HTTPError(message)``
  puts the message where the status belongs, and the error handler itself
  fails). The subclasses here resolve the Thing and the affordance first and
  answer problem+json 4xx naming it (404 unknown, 405 read-only, 400 body not
  JSON), answer OPTIONS, and turn any error into problem+json; the request
  handling proper is wotpy's.
- The HTTP Application's default handler answers problem+json 404 for paths no
  route serves, and its ``ProblemTransform`` turns tornado's HTML error page of
  any other handler (a method a route lacks: 405) into problem+json.
"""

from __future__ import annotations

import json
import logging
import socket
import ssl
from collections.abc import Callable, Sequence
from typing import Any

import tornado.httpserver
import tornado.netutil
import tornado.web
import tornado.websocket
from slugify import slugify
from wotpy.protocols.http.handlers.action import ActionInvokeHandler
from wotpy.protocols.http.handlers.event import EventObserverHandler
from wotpy.protocols.http.handlers.property import PropertyObserverHandler, PropertyReadWriteHandler
from wotpy.protocols.http.server import HTTPServer
from wotpy.protocols.ws.server import WebsocketServer
from wotpy.wot.dictionaries.thing import ThingFragment
from wotpy.wot.exposed.thing import ExposedThing
from wotpy.wot.exposed.thing_set import ExposedThingSet
from wotpy.wot.servient import Servient
from wotpy.wot.thing import Thing

from wott_hub.errors import WottHubError, http_status

from .problem import MethodNotAllowed, NotFoundHandler, ProblemTransform, write_problem

__all__ = [
    "WOTPY_ROUTE_HANDLERS", "FastThing", "HubHTTPServer", "HubServient", "HubWebsocketServer",
    "IndexedExposedThingSet",
]

log = logging.getLogger(__name__)


class FastThing(Thing):
    """A wotpy Thing whose title, id and URL name are constant-time attributes."""

    _fast_title: str
    _fast_id: str | None
    _fast_url_name: str

    def __init__(self, thing_fragment: ThingFragment) -> None:
        super().__init__(thing_fragment=thing_fragment)
        init = thing_fragment._init  # the raw dict wotpy keeps; title is read-only in wotpy
        title = init["title"]
        object.__setattr__(self, "_fast_title", title)
        object.__setattr__(self, "_fast_id", init.get("id"))
        object.__setattr__(self, "_fast_url_name", slugify(title))

    @property
    def title(self) -> str:
        return self._fast_title

    @property
    def id(self) -> str | None:
        return self._fast_id

    @property
    def url_name(self) -> str:
        return self._fast_url_name


class IndexedExposedThingSet(ExposedThingSet):
    """ExposedThingSet with O(1) lookups by title, URL name and Thing."""

    def __init__(self) -> None:
        super().__init__()
        self._by_name: dict[str, ExposedThing] = {}
        self._by_thing: dict[int, ExposedThing] = {}

    def contains(self, exposed_thing: ExposedThing) -> bool:
        return self._by_thing.get(id(exposed_thing.thing)) is exposed_thing

    def add(self, exposed_thing: ExposedThing) -> None:
        thing = exposed_thing.thing
        title, url_name = thing.title, thing.url_name
        if title in self._by_name or url_name in self._by_name:
            raise ValueError(f"Duplicate Exposed Thing: {title}")
        self._exposed_things[title] = exposed_thing
        self._by_name[title] = exposed_thing
        self._by_name[url_name] = exposed_thing
        self._by_thing[id(thing)] = exposed_thing

    def remove(self, thing_title: str) -> None:
        exposed_thing = self.find_by_thing_title(thing_title)
        if exposed_thing is None:
            raise ValueError(f"Unknown Exposed Thing: {thing_title}")
        thing = exposed_thing.thing
        self._exposed_things.pop(thing.title, None)
        self._by_name.pop(thing.title, None)
        self._by_name.pop(thing.url_name, None)
        self._by_thing.pop(id(thing), None)

    def find_by_thing_title(self, thing_title: str) -> ExposedThing | None:
        return self._by_name.get(thing_title)

    def find_by_interaction(self, interaction: Any) -> ExposedThing | None:
        return self._by_thing.get(id(interaction.thing))


class HubServient(Servient):
    """The fleet's one servient: indexed Things, no O(N²) form regeneration.

    ``catalogue_app`` (optional) replaces wotpy's catalogue application, whose
    handlers regenerate and re-validate every TD on each request.
    """

    _catalogue_port: int | None
    _catalogue_server: tornado.httpserver.HTTPServer | None

    def __init__(self, hostname: str, *, catalogue_port: int | None = None,
                 catalogue_app: Callable[[], tornado.web.Application] | None = None) -> None:
        super().__init__(hostname=hostname, catalogue_port=catalogue_port or None,
                         create_default_forms=False)
        self._exposed_thing_set = IndexedExposedThingSet()
        self._catalogue_app_factory = catalogue_app

    def _build_td_catalogue_app(self) -> tornado.web.Application:
        if self._catalogue_app_factory is not None:
            return self._catalogue_app_factory()
        app: tornado.web.Application = super()._build_td_catalogue_app()
        return app

    def _start_catalogue(self) -> None:
        if self._catalogue_server or not self._catalogue_port:
            return
        app = self._build_td_catalogue_app()
        self._catalogue_server = tornado.httpserver.HTTPServer(app)
        self._catalogue_server.add_sockets(tornado.netutil.bind_sockets(self._catalogue_port,
                                                                        address=self.hostname))

    def enable_exposed_thing(self, thing_title: str) -> None:
        exposed_thing = self.get_exposed_thing(thing_title)
        for server in self._servers.values():
            server.add_exposed_thing(exposed_thing)
            if self._create_default_forms:  # only this Thing's forms, not every Thing's
                self._add_interaction_forms(server, exposed_thing)
        self._enabled_exposed_thing_titles.add(exposed_thing.title)

    def disable_exposed_thing(self, thing_title: str) -> None:
        exposed_thing = self.get_exposed_thing(thing_title)
        if exposed_thing.title not in self._enabled_exposed_thing_titles:
            raise ValueError(f"ExposedThing {thing_title} is already disabled")
        for server in self._servers.values():
            server.remove_exposed_thing(exposed_thing.title)
            if self._create_default_forms:
                self._clean_protocol_forms(exposed_thing, server.protocol)
        self._enabled_exposed_thing_titles.remove(exposed_thing.title)


_SINGULAR = {"properties": "property", "actions": "action", "events": "event"}


class _WotpyRoute(tornado.web.RequestHandler):
    """What every wotpy HTTP route gets: the Thing and affordance resolved first, problem+json errors.

    ``kind`` is the TD key of the affordance the route serves. The resolved
    ExposedThing is left for wotpy's handler, which resolves it again (cheap:
    the sets are indexed).
    """

    kind = "properties"
    _server: Any

    def set_default_headers(self) -> None:
        self.set_header("Access-Control-Allow-Origin", "*")

    def options(self, *_args: Any, **_kwargs: Any) -> None:
        self.set_header("Access-Control-Allow-Methods", "GET, PUT, POST, OPTIONS")
        self.set_header("Access-Control-Allow-Headers", "Accept, Content-Type")
        self.set_status(204)

    def prepare(self) -> None:
        if self.request.method == "OPTIONS":
            return
        thing_name, name = self.path_kwargs["thing_name"], self.path_kwargs["name"]
        try:
            exposed = self._server.get_exposed_thing(thing_name)
        except ValueError:
            raise tornado.web.HTTPError(404, reason=f"Unknown Thing {thing_name!r}") from None
        affordances = getattr(exposed.thing, self.kind)
        if name not in affordances:
            what = _SINGULAR[self.kind]
            raise tornado.web.HTTPError(404, reason=f"Thing {thing_name!r} has no {what} {name!r}")
        if self.request.method in ("PUT", "POST"):
            try:
                json.loads(self.request.body or b"null")
            except (ValueError, RecursionError) as e:
                raise tornado.web.HTTPError(400, reason=f"the request body is not JSON: {e}") from None
        self.check(exposed, affordances[name])

    def check(self, exposed: Any, affordance: Any) -> None:
        """Refuse, with the HTTP error naming the affordance, what wotpy would fail on."""

    def send_error(self, status_code: Any = 500, **kwargs: Any) -> None:
        if not isinstance(status_code, int):  # wotpy's HTTPError(message): a write wotpy refused
            kwargs["reason"], status_code = str(status_code), 400
        super().send_error(status_code, **kwargs)

    def write_error(self, status_code: int, **kwargs: Any) -> None:
        write_problem(self, status_code, **kwargs)


class _PropertyRoute(_WotpyRoute, PropertyReadWriteHandler):
    def check(self, exposed: Any, affordance: Any) -> None:
        if self.request.method == "PUT" and not affordance.writable:
            raise MethodNotAllowed("GET, OPTIONS",
                                   f"Property {affordance.name!r} of {exposed.thing.title!r} is read-only")


class _PropertyObserveRoute(_WotpyRoute, PropertyObserverHandler):
    pass


class _ActionRoute(_WotpyRoute, ActionInvokeHandler):
    kind = "actions"

    def check(self, exposed: Any, affordance: Any) -> None:
        # wotpy's default handler fails every invocation (NotImplementedError, a 500)
        handler = exposed._get_handler(exposed.HandlerKeys.INVOKE_ACTION, affordance)
        if handler == exposed._default_invoke_action_handler:
            raise tornado.web.HTTPError(404, reason=f"Action {affordance.name!r} of {exposed.thing.title!r} "
                                                    f"is not served on this route (see its form in the TD)")

    async def post(self, thing_name: str, name: str) -> None:
        try:
            invoked = super().post(thing_name, name)  # wotpy's coroutine
            if invoked is not None:
                await invoked
        except tornado.web.HTTPError as e:  # wotpy wraps the action's own error in a 500
            cause = e.__context__
            if isinstance(cause, WottHubError):
                raise tornado.web.HTTPError(http_status(cause), reason=str(cause)) from None
            if isinstance(cause, ValueError | TypeError):
                raise tornado.web.HTTPError(400, reason=f"input of action {name!r}: {cause}") from None
            log.error("action %r of %r failed", name, thing_name, exc_info=cause)
            raise


class _EventObserveRoute(_WotpyRoute, EventObserverHandler):
    kind = "events"


WOTPY_ROUTE_HANDLERS: dict[type, type] = {
    PropertyReadWriteHandler: _PropertyRoute,
    PropertyObserverHandler: _PropertyObserveRoute,
    ActionInvokeHandler: _ActionRoute,
    EventObserverHandler: _EventObserveRoute,
}
"""wotpy's HTTP route handler classes and the checked subclasses that serve their routes instead."""


class _Prebound:
    """Bind the listening socket on the configured address before the servient starts."""

    _sockets: list[socket.socket] | None = None
    _host = "127.0.0.1"
    _port: int  # set by wotpy's server __init__
    _form_port: int
    _server: tornado.httpserver.HTTPServer | None

    def bind(self) -> int:
        if not self._sockets:
            self._sockets = tornado.netutil.bind_sockets(self._port, address=self._host)
            port = self._sockets[0].getsockname()[1]
            if self._form_port in (self._port, 0):
                self._form_port = port
            self._port = port
        return self._port

    def _serve(self, app: tornado.web.Application,
               ssl_context: ssl.SSLContext | None) -> tornado.httpserver.HTTPServer:
        self.bind()
        server = tornado.httpserver.HTTPServer(app, ssl_options=ssl_context, xheaders=False)
        server.add_sockets(self._sockets or ())  # bind() just filled them
        return server

    async def _close(self) -> None:
        server = self._server
        if server is None:
            return
        server.stop()
        self._server = None
        self._sockets = None
        await server.close_all_connections()


class HubHTTPServer(_Prebound, HTTPServer):
    """wotpy's HTTP binding on one address, with extra handlers before wotpy's routes."""

    def __init__(self, port: int = 8080, *, host: str = "127.0.0.1",
                 handlers: Sequence[tuple[Any, ...]] = ()) -> None:
        self._extra_handlers = list(handlers)
        self._host = host
        super().__init__(port=port)
        self._exposed_thing_set = IndexedExposedThingSet()

    def _build_app(self) -> tornado.web.Application:
        wotpy_app = super()._build_app()
        wotpy_rules = [(r.matcher.regex.pattern, WOTPY_ROUTE_HANDLERS.get(r.target, r.target),
                        r.target_kwargs) for r in wotpy_app.wildcard_router.rules]
        return tornado.web.Application(self._extra_handlers + wotpy_rules,
                                       default_handler_class=NotFoundHandler, transforms=[ProblemTransform])

    def add_handlers(self, rules: Sequence[tuple[Any, ...]]) -> None:
        """Mount more routes (they take precedence over the ones given before); works while running."""
        self._app.add_handlers(r".*", list(rules))

    async def start(self, servient: Servient | None = None) -> None:
        self._servient = servient
        self._server = self._serve(self.app, self._ssl_context)

    async def stop(self) -> None:
        await self._close()


class HubWebsocketServer(_Prebound, WebsocketServer):
    """wotpy's WebSocket binding on one address, served by ``handler_class``."""

    def __init__(self, port: int = 8081, *, host: str = "127.0.0.1",
                 handler_class: type[tornado.websocket.WebSocketHandler] | None = None,
                 handler_kwargs: dict[str, Any] | None = None) -> None:
        self._host = host
        self._handler_class = handler_class
        self._handler_kwargs = handler_kwargs or {}
        super().__init__(port=port)
        self._form_port = self._port
        self._exposed_thing_set = IndexedExposedThingSet()

    def _build_app(self) -> tornado.web.Application:
        if self._handler_class is None:
            app: tornado.web.Application = super()._build_app()
            return app
        return tornado.web.Application([
            (r"/(?P<name>[^\/]+)", self._handler_class,
             {"websocket_server": self, **self._handler_kwargs}),
        ])

    async def start(self, servient: Servient | None = None) -> None:
        self._servient = servient
        self._server = self._serve(self.app, self._ssl_context)

    async def stop(self) -> None:
        await self._close()
