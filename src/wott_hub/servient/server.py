"""One wotpy servient serving the whole fleet, with the hub's routes on its HTTP port.

``HubServer`` owns the servient (HTTP + WebSocket bindings, optional wotpy
catalogue port), the registry of served Things and the handlers' shared
context. ``expose`` registers a Thing everywhere at once: the hub's routes
(TD, properties, SSE), wotpy's ExposedThing (WebSocket JSON-RPC, wotpy's own
HTTP routes, in-process wotpy observers) and the event plane's wotpy bridge.
"""

from __future__ import annotations

import asyncio
import json
import ssl
from collections.abc import Awaitable, Callable, Sequence
from typing import Any

import tornado.web
from wotpy.wot.dictionaries.thing import ThingFragment
from wotpy.wot.events import EmittedEvent, PropertyChangeEmittedEvent, PropertyChangeEventInit
from wotpy.wot.exposed.thing import ExposedThing

from wott_hub.events.plane import EventPlane
from wott_hub.events.record import KIND_EVENT, Record
from wott_hub.security.audit import AuditLog
from wott_hub.security.gate import guard
from wott_hub.security.policy import AccessPolicy
from wott_hub.td.defaults import state_defaults
from wott_hub.web import routes as web_routes  # the twin: / and /twin/*

from .adapters import FastThing, HubHTTPServer, HubServient, HubWebsocketServer
from .context import ServingContext
from .forms import FormLayout
from .http import CatalogueHandler, TDHandler
from .routes import routes
from .things import ServedThing, ThingRegistry
from .ws import FastWebsocketHandler

__all__ = ["ALL_INTERFACES", "HubServer"]

ALL_INTERFACES = ("0.0.0.0", "::", "")
"""Hosts that mean "listen on every interface" (clients are told 127.0.0.1 instead)."""


class _WotpyBridge:
    """Feeds a Thing's records to wotpy's reactive stream, only while someone observes it."""

    def __init__(self, exposed: ExposedThing) -> None:
        self.subject = exposed._events_stream

    @property
    def active(self) -> bool:
        return bool(self.subject.observers)

    def __call__(self, rec: Record) -> None:
        data = json.loads(rec.data)
        if rec.kind == KIND_EVENT:
            self.subject.on_next(EmittedEvent(init=data, name=rec.name))
        else:
            self.subject.on_next(PropertyChangeEmittedEvent(init=PropertyChangeEventInit(rec.name, data)))


def _wotpy_fragment(served: ServedThing) -> ThingFragment:
    """The TD without forms, titled by the Thing id (wotpy keys and routes Things by title)."""
    td = served.td
    doc = {k: v for k, v in td.items() if k not in ("forms", "base")}
    doc["title"] = served.id
    for key in ("properties", "events", "actions"):
        if key in td:
            doc[key] = {n: {k: v for k, v in a.items() if k != "forms"} for n, a in td[key].items()}
    return ThingFragment(doc)


class HubServer:
    def __init__(self, plane: EventPlane, *, host: str = "127.0.0.1", http_port: int = 8080,
                 ws_port: int | None = 8081, public_host: str | None = None, catalogue_port: int = 0,
                 extra_handlers: Sequence[tuple[Any, ...]] = (), policy: AccessPolicy | None = None,
                 ssl_context: ssl.SSLContext | None = None, audit: AuditLog | None = None) -> None:
        self.plane = plane
        # who may do what (wott_hub.security): checked once per request/handshake by each server's app
        self.policy = policy or AccessPolicy()
        self.audit = audit
        self.ssl_context = ssl_context
        self.host = host
        self.public_host = public_host or (host if host not in ALL_INTERFACES else "127.0.0.1")
        self.things = ThingRegistry()
        # told of every Thing served and removed, whoever does it (the hub's network: directory, mDNS)
        self.on_expose: list[Callable[[ServedThing], None]] = []
        self.on_remove: list[Callable[[ServedThing], None]] = []
        self.ctx = ServingContext(plane, self.things,
                                  FormLayout(f"{self.policy.http_scheme}://{self.public_host}:{http_port}"))
        self.http = HubHTTPServer(http_port, host=host, handlers=[*extra_handlers, *routes(self.ctx),
                                                                     *web_routes()])
        self.ws = (HubWebsocketServer(ws_port, host=host, handler_class=FastWebsocketHandler,
                                      handler_kwargs={"ctx": self.ctx})
                   if ws_port is not None else None)
        for server in (self.http, self.ws):
            if server is not None:
                guard(server.app, self.policy, audit)
                server._ssl_context = ssl_context  # https/wss (wotpy servers read it when they start)
        self.servient = HubServient(self.public_host, catalogue_port=catalogue_port or None,
                                    catalogue_app=self._catalogue_app)
        self.servient.add_server(self.http)
        if self.ws is not None:
            self.servient.add_server(self.ws)
        self._started = False

    # --- lifecycle ----------------------------------------------------------------

    def bind(self) -> FormLayout:
        """Bind the ports (0 = any free one) so TDs can name them before anything starts."""
        http_port = self.http.bind()
        ws_base = None
        if self.ws is not None:
            ws_base = f"{self.policy.ws_scheme}://{self.public_host}:{self.ws.bind()}"
        self.ctx.layout = FormLayout(f"{self.policy.http_scheme}://{self.public_host}:{http_port}", ws_base)
        return self.ctx.layout

    @property
    def layout(self) -> FormLayout:
        return self.ctx.layout

    @property
    def http_port(self) -> int:
        port: int = self.http.port
        return port

    @property
    def ws_port(self) -> int | None:
        return self.ws.port if self.ws is not None else None

    async def start(self, *, streams_ready: bool = True) -> None:
        """Start serving. ``streams_ready=False``: stream requests wait until the owner sets
        ``ctx.streams_ready`` (the hub does, once each stream continues its recorded sequence)."""
        self.bind()
        await self.servient.start()
        self.ctx.start()
        if streams_ready:
            self.ctx.streams_ready.set()
        self._started = True

    async def stop(self) -> None:
        if not self._started:
            return
        self._started = False
        self.ctx.close_streams()
        await asyncio.sleep(0)  # let stream handlers finish their responses
        await self.servient.shutdown()

    def add_handlers(self, rules: Sequence[tuple[Any, ...]]) -> None:
        """Mount more routes on the hub's HTTP port (e.g. the TD directory)."""
        self.http.add_handlers(rules)

    def _catalogue_app(self) -> tornado.web.Application:
        """wotpy's catalogue port, same paths as wotpy's (``/``, ``/<name>``), from cached TDs."""
        k = {"ctx": self.ctx}
        app = tornado.web.Application([(r"/", CatalogueHandler, k),
                                       (r"/(?P<thing_id>[^/]+)/?", TDHandler, k)])
        return guard(app, self.policy, self.audit)

    # --- Things -------------------------------------------------------------------

    def expose(self, served: ServedThing) -> ExposedThing:
        """Serve a Thing on every binding. Its stream must already be on the event plane."""
        self.policy.secure_td(served.td)  # its securityDefinitions say what the gate does
        state_defaults(served.td)  # readOnly, observable, safe, contentType...: stated (td/defaults.py)
        thing = FastThing(_wotpy_fragment(served))
        exposed = ExposedThing(servient=self.servient, thing=thing)
        for name in served.property_names:
            exposed.set_property_read_handler(name, _reader(served, name))
        self.servient.add_exposed_thing(exposed)
        try:
            self.things.add(served, thing.url_name)
        except ValueError:
            self.servient.remove_exposed_thing(thing.title)
            raise
        self.servient.enable_exposed_thing(thing.title)
        served.exposed = exposed
        self.plane.add_tap(served.id, _WotpyBridge(exposed))
        for listener in self.on_expose:
            listener(served)
        return exposed

    def remove(self, thing_id: str) -> None:
        served = self.things.remove(thing_id)
        if served is None:
            return
        if served.exposed is not None:
            self.servient.remove_exposed_thing(served.exposed.thing.title)
        for listener in self.on_remove:
            listener(served)

    def td_url(self, thing_id: str) -> str:
        return self.layout.thing_url(thing_id)


def _reader(served: ServedThing, name: str) -> Callable[[], Awaitable[Any]]:
    async def read() -> Any:
        return json.loads(served.read(name) or "null")

    return read
