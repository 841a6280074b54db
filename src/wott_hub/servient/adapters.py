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
"""

from __future__ import annotations

import socket
from collections.abc import Callable, Sequence
from typing import Any

import tornado.httpserver
import tornado.netutil
import tornado.web
from slugify import slugify
from wotpy.protocols.http.server import HTTPServer
from wotpy.protocols.ws.server import WebsocketServer
from wotpy.wot.exposed.thing_set import ExposedThingSet
from wotpy.wot.servient import Servient
from wotpy.wot.thing import Thing

__all__ = [
    "FastThing", "HubHTTPServer", "HubServient", "HubWebsocketServer", "IndexedExposedThingSet",
]


class FastThing(Thing):
    """A wotpy Thing whose title, id and URL name are constant-time attributes."""

    def __init__(self, thing_fragment) -> None:
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
        self._by_name: dict[str, Any] = {}
        self._by_thing: dict[int, Any] = {}

    def contains(self, exposed_thing) -> bool:
        return self._by_thing.get(id(exposed_thing.thing)) is exposed_thing

    def add(self, exposed_thing) -> None:
        thing = exposed_thing.thing
        title, url_name = thing.title, thing.url_name
        if title in self._by_name or url_name in self._by_name:
            raise ValueError(f"Duplicate Exposed Thing: {title}")
        self._exposed_things[title] = exposed_thing
        self._by_name[title] = exposed_thing
        self._by_name[url_name] = exposed_thing
        self._by_thing[id(thing)] = exposed_thing

    def remove(self, thing_title) -> None:
        exposed_thing = self.find_by_thing_title(thing_title)
        if exposed_thing is None:
            raise ValueError(f"Unknown Exposed Thing: {thing_title}")
        thing = exposed_thing.thing
        self._exposed_things.pop(thing.title, None)
        self._by_name.pop(thing.title, None)
        self._by_name.pop(thing.url_name, None)
        self._by_thing.pop(id(thing), None)

    def find_by_thing_title(self, thing_title):
        return self._by_name.get(thing_title)

    def find_by_interaction(self, interaction):
        return self._by_thing.get(id(interaction.thing))


class HubServient(Servient):
    """The fleet's one servient: indexed Things, no O(N²) form regeneration.

    ``catalogue_app`` (optional) replaces wotpy's catalogue application, whose
    handlers regenerate and re-validate every TD on each request.
    """

    def __init__(self, hostname: str, *, catalogue_port: int | None = None,
                 catalogue_app: Callable[[], tornado.web.Application] | None = None) -> None:
        super().__init__(hostname=hostname, catalogue_port=catalogue_port or None,
                         create_default_forms=False)
        self._exposed_thing_set = IndexedExposedThingSet()
        self._catalogue_app_factory = catalogue_app

    def _build_td_catalogue_app(self):
        if self._catalogue_app_factory is not None:
            return self._catalogue_app_factory()
        return super()._build_td_catalogue_app()

    def _start_catalogue(self) -> None:
        if self._catalogue_server or not self._catalogue_port:
            return
        app = self._build_td_catalogue_app()
        self._catalogue_server = tornado.httpserver.HTTPServer(app)
        self._catalogue_server.add_sockets(tornado.netutil.bind_sockets(self._catalogue_port,
                                                                        address=self.hostname))

    def enable_exposed_thing(self, thing_title) -> None:
        exposed_thing = self.get_exposed_thing(thing_title)
        for server in self._servers.values():
            server.add_exposed_thing(exposed_thing)
            if self._create_default_forms:  # only this Thing's forms, not every Thing's
                self._add_interaction_forms(server, exposed_thing)
        self._enabled_exposed_thing_titles.add(exposed_thing.title)

    def disable_exposed_thing(self, thing_title) -> None:
        exposed_thing = self.get_exposed_thing(thing_title)
        if exposed_thing.title not in self._enabled_exposed_thing_titles:
            raise ValueError(f"ExposedThing {thing_title} is already disabled")
        for server in self._servers.values():
            server.remove_exposed_thing(exposed_thing.title)
            if self._create_default_forms:
                self._clean_protocol_forms(exposed_thing, server.protocol)
        self._enabled_exposed_thing_titles.remove(exposed_thing.title)


class _Prebound:
    """Bind the listening socket on the configured address before the servient starts."""

    _sockets: list[socket.socket] | None = None
    _host = "127.0.0.1"

    def bind(self) -> int:
        if not self._sockets:
            self._sockets = tornado.netutil.bind_sockets(self._port, address=self._host)
            port = self._sockets[0].getsockname()[1]
            if self._form_port in (self._port, 0):
                self._form_port = port
            self._port = port
        return self._port

    def _serve(self, app: tornado.web.Application, ssl_context) -> tornado.httpserver.HTTPServer:
        self.bind()
        server = tornado.httpserver.HTTPServer(app, ssl_options=ssl_context, xheaders=False)
        server.add_sockets(self._sockets)
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
                 handlers: Sequence[tuple] = ()) -> None:
        self._extra_handlers = list(handlers)
        self._host = host
        super().__init__(port=port)
        self._exposed_thing_set = IndexedExposedThingSet()

    def _build_app(self) -> tornado.web.Application:
        wotpy_app = super()._build_app()
        wotpy_rules = [(r.matcher.regex.pattern, r.target, r.target_kwargs)
                       for r in wotpy_app.wildcard_router.rules]
        return tornado.web.Application(self._extra_handlers + wotpy_rules)

    def add_handlers(self, rules: Sequence[tuple]) -> None:
        """Mount more routes (they take precedence over the ones given before); works while running."""
        self._app.add_handlers(r".*", list(rules))

    async def start(self, servient=None) -> None:
        self._servient = servient
        self._server = self._serve(self.app, self._ssl_context)

    async def stop(self) -> None:
        await self._close()


class HubWebsocketServer(_Prebound, WebsocketServer):
    """wotpy's WebSocket binding on one address, served by ``handler_class``."""

    def __init__(self, port: int = 8081, *, host: str = "127.0.0.1", handler_class=None,
                 handler_kwargs: dict | None = None) -> None:
        self._host = host
        self._handler_class = handler_class
        self._handler_kwargs = handler_kwargs or {}
        super().__init__(port=port)
        self._form_port = self._port
        self._exposed_thing_set = IndexedExposedThingSet()

    def _build_app(self) -> tornado.web.Application:
        if self._handler_class is None:
            return super()._build_app()
        return tornado.web.Application([
            (r"/(?P<name>[^\/]+)", self._handler_class,
             {"websocket_server": self, **self._handler_kwargs}),
        ])

    async def start(self, servient=None) -> None:
        self._servient = servient
        self._server = self._serve(self.app, self._ssl_context)

    async def stop(self) -> None:
        await self._close()
