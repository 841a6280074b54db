"""Who may do what on the hub: the scope each request needs, and the TD that says so.

One ``AccessPolicy`` per hub. ``required`` maps a request (method, path) to the
scope it needs; ``admit`` checks the credential a request carries against it, once
per request, stream or WebSocket handshake (never per event). ``secure_td`` writes the
same rules into a TD: ``securityDefinitions`` and ``security``, so what a TD declares
is what the server does.

Open mode (``enforced`` false): a hub on loopback with no credentials configured, or
one started with ``--insecure``. TDs then declare ``nosec`` and every request passes.

Credentials: ``Authorization: Bearer <token>`` (every HTTP client, node-wot,
``wott_directory.DirectoryClient``, the twin's fetches), or the query parameter
``access_token`` (RFC 6750 §2.3) for clients that cannot set headers: browsers'
``EventSource`` and ``WebSocket``, wotpy's WebSocket client. Public, even when
enforced: CORS preflights (they never carry credentials), ``/healthz``, the Tactile
JSON-LD context and the twin's static page shell (no data: the page asks for a token
and fetches everything else with it).
"""

from __future__ import annotations

import copy
import re
import secrets
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import urlsplit

from .scopes import Scope
from .tokens import StoredToken, TokenStore

__all__ = ["BEARER", "BEARER_EITHER", "BEARER_QUERY", "CONTROL_ACTIONS", "AccessPolicy", "Decision",
           "Principal", "allows", "credential"]

BEARER = "bearer_sc"
BEARER_QUERY = "bearer_query_sc"
BEARER_EITHER = "bearer_either_sc"
NOSEC = "nosec_sc"
QUERY_PARAM = "access_token"
REALM = "wott-hub"

_SAFE = frozenset({"GET", "HEAD"})
_PUBLIC = re.compile(r"^/(?:healthz|contexts/[^/]+|twin(?:/[A-Za-z0-9_.-]+)?/?|twin/vendor/[A-Za-z0-9_.-]+"
                     r"|favicon\.ico)?$")
ADMIN_ACTIONS = frozenset({"addDevice", "removeDevice", "restartDevice"})
"""Actions that manage the fleet (the hub Thing's, hub/management.py): ``admin``."""
CONTROL_ACTIONS = frozenset({"historyExport"})
"""Actions that are ``safe`` (they change nothing) but cost the hub a thread and a core for as long as
they run (hub/exports.py): ``control``, not ``read``."""
_DIRECTORY = re.compile(r"^(?:/things(?:/.*)?|/search/.*|/events(?:/.*)?|/\.well-known/wot)$")


@dataclass(frozen=True)
class Principal:
    """Who made a request: a token's name and scope (never the token)."""

    name: str
    scope: Scope


ANONYMOUS = Principal("-", Scope.ADMIN)  # open mode: everyone may do everything


@dataclass(frozen=True)
class Decision:
    status: int  # 200: admitted; 401 or 403: refused; 503: too many token checks waiting
    principal: Principal | None = None
    reason: str = ""
    required: Scope | None = None
    error: str = ""  # RFC 6750 error code: invalid_token, insufficient_scope

    @property
    def admitted(self) -> bool:
        return self.status == 200

    def www_authenticate(self) -> str:
        out = f'Bearer realm="{REALM}"'
        if self.error:
            out += f', error="{self.error}"'
        if self.required is not None and self.error == "insufficient_scope":
            out += f', scope="{self.required}"'
        return out


@dataclass(eq=False)
class AccessPolicy:
    store: TokenStore | None = None
    enforced: bool = False
    tls: bool = False
    cors_origins: tuple[str, ...] = ()
    restrict_cors: bool = False
    # the hub's own credential for its embedded directory (never leaves the process)
    internal_token: str = field(default_factory=lambda: secrets.token_urlsafe(32))
    # the path of every action form of the TDs served -> its scope (``secure_td`` fills it)
    action_scopes: dict[str, Scope] = field(default_factory=dict)

    @property
    def http_scheme(self) -> str:
        return "https" if self.tls else "http"

    @property
    def ws_scheme(self) -> str:
        return "wss" if self.tls else "ws"

    def required(self, method: str, path: str) -> Scope | None:
        """The scope ``method path`` needs; None: public. An action declared ``safe`` in its TD
        (the history API's queries) needs ``read``, unless it is costly (``CONTROL_ACTIONS``); a
        fleet action ``admin``; any other ``control``."""
        if method == "OPTIONS":
            return None
        if method in _SAFE:
            return None if _PUBLIC.match(path) else Scope.READ
        if _DIRECTORY.match(path):
            return Scope.ADMIN
        return self.action_scopes.get(path, Scope.CONTROL)

    def to_check(self, method: str, path: str, headers: Mapping[str, str],
                 query_token: str | None = None) -> str | None:
        """The token a request carries when admitting it needs a hash first (``TokenStore.verify_async``,
        off the event loop); None when ``admit`` can answer at once (open mode, a public route, no
        token, a token whose answer is remembered)."""
        if not self.enforced or self.store is None or self.required(method, path) is None:
            return None
        token = credential(headers, query_token)
        if not token or self.store.known(token)[0]:
            return None
        return token

    def admit(self, method: str, path: str, headers: Mapping[str, str], query_token: str | None = None, *,
              checked: tuple[StoredToken | None] | None = None) -> Decision:
        """Admit or refuse a request. ``checked``: the answer ``verify_async`` gave for its token (the
        gate's way: the hash ran off the loop); without it a token is checked here (``verify``)."""
        if not self.enforced:
            return Decision(200, ANONYMOUS)
        required = self.required(method, path)
        if required is None:
            return Decision(200, None)
        token = credential(headers, query_token)
        if not token:
            return Decision(401, None, "this route needs 'Authorization: Bearer <token>' "
                                       f"(or ?{QUERY_PARAM}=<token>)", required)
        if checked is not None:
            stored = checked[0]
        else:
            stored = self.store.verify(token) if self.store is not None else None
        if stored is None:
            return Decision(401, None, "the bearer token is not valid", required, "invalid_token")
        principal = _principal(stored)
        if not principal.scope.grants(required):
            return Decision(403, principal, f"token {principal.name!r} has scope {principal.scope}; "
                                            f"this needs {required}", required, "insufficient_scope")
        return Decision(200, principal, required=required)

    def cors_origin(self, origin: str | None) -> str | None:
        """The ``Access-Control-Allow-Origin`` to answer ``origin`` with (None: none)."""
        if not self.restrict_cors:
            return "*"
        return origin if origin is not None and origin in self.cors_origins else None

    # --- TDs ----------------------------------------------------------------------------

    def security_definitions(self) -> dict[str, Any]:
        if not self.enforced:
            return {NOSEC: {"scheme": "nosec"}}
        return {
            BEARER: {"scheme": "bearer", "in": "header", "name": "Authorization", "format": "opaque",
                     "description": "A wott-hub token (wott_<id>_<secret>) with scope read (TDs, "
                                    "properties, streams), control (actions) or admin (directory "
                                    "writes): 'Authorization: Bearer <token>'."},
            BEARER_QUERY: {"scheme": "bearer", "in": "query", "name": QUERY_PARAM, "format": "opaque",
                           "description": "The same token as the access_token query parameter, for "
                                          "clients that cannot set headers (WebSocket, EventSource)."},
            BEARER_EITHER: {"scheme": "combo", "oneOf": [BEARER, BEARER_QUERY],
                            "description": "Streams and WebSockets: the header or the query parameter."},
        }

    def secure_td(self, td: dict[str, Any]) -> dict[str, Any]:
        """Write this policy's schemes into ``td`` (in place): every form takes the header; SSE and
        WebSocket forms the header or the query parameter (``combo``/``oneOf``). Returns ``td``."""
        td["securityDefinitions"] = self.security_definitions()
        td["security"] = [BEARER] if self.enforced else [NOSEC]
        for name, aff in (td.get("actions") or {}).items():
            scope = (Scope.ADMIN if name in ADMIN_ACTIONS else
                     Scope.READ if aff.get("safe") is True and name not in CONTROL_ACTIONS else Scope.CONTROL)
            for form in aff.get("forms") or ():
                if isinstance(form.get("href"), str):
                    self.action_scopes[urlsplit(form["href"]).path] = scope
        if self.enforced:
            for form in _forms(td):
                href = form.get("href", "")
                if (isinstance(href, str) and href.startswith(("ws://", "wss://"))) or (
                        form.get("subprotocol") == "sse"):
                    form["security"] = [BEARER_EITHER]
            _add_long_poll_forms(td)
        return td


def allows(request: Any, scope: Scope) -> bool:
    """Whether the request the gate admitted (a WebSocket's handshake) carries ``scope``: a
    socket opened with a ``read`` token may not write or invoke over it. No gate: allowed."""
    principal = getattr(request, "wott_principal", None)
    return principal is None or principal.scope.grants(scope)


def _add_long_poll_forms(td: dict[str, Any]) -> None:
    """Before each SSE form of an event or observable property, a ``longpoll`` form of the same
    stream under the Thing's ``security`` (the header): the form node-wot 0.9.2 subscribes with.

    node-wot opens SSE with ``new EventSource(href)``, which sends no credential at all; it picks
    the first form listing the operation, sets its client's credentials once from that form's
    ``security`` (a ``combo`` it cannot apply: no credential for any later request either; any
    form-level scheme: "No Bearer credentials for Thing"), and signs a long poll's requests with
    the header like a read. So a secured TD offers the long poll first, without form-level
    security and without ``htv:methodName``: node-wot's handshake is a HEAD only then (with GET
    declared it is a GET, which waits for a record and times out after 1 s). Measured in
    tests/interop/test_nodewot_credentials.py; clients choosing forms by ``subprotocol: "sse"``
    (browsers, wott-client, the twin, wot-remote) are unaffected. A long poll answers one record
    per request and node-wot sends no ``Last-Event-ID``: records between two polls are not
    delivered (docs/security.md)."""
    for kind in ("properties", "events"):
        for aff in (td.get(kind) or {}).values():
            forms = aff.get("forms") if isinstance(aff, dict) else None
            if not isinstance(forms, list) or any(
                    isinstance(f, dict) and f.get("subprotocol") == "longpoll" for f in forms):
                continue
            at = next((i for i, f in enumerate(forms) if isinstance(f, dict) and f.get("subprotocol") == "sse"
                       and isinstance(f.get("href"), str)), None)
            if at is None:
                continue
            sse = forms[at]
            poll = {"href": sse["href"], "op": copy.deepcopy(sse.get("op", [])), "subprotocol": "longpoll",
                    "contentType": sse.get("contentType", "application/json")}
            forms.insert(at, poll)


def _forms(td: dict[str, Any]) -> Iterator[dict[str, Any]]:
    yield from td.get("forms") or ()
    for key in ("properties", "actions", "events"):
        for aff in (td.get(key) or {}).values():
            yield from aff.get("forms") or ()


def credential(headers: Mapping[str, str], query_token: str | None = None) -> str | None:
    """The token a request presents: ``Authorization: Bearer``, else ``?access_token=``."""
    return _bearer(headers.get("Authorization")) or query_token or None


def _bearer(header: str | None) -> str | None:
    if not header:
        return None
    kind, _, value = header.strip().partition(" ")
    return value.strip() or None if kind.lower() == "bearer" else None


def _principal(stored: StoredToken) -> Principal:
    return Principal(stored.name, stored.scope_level)
