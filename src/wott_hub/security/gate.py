"""The one place a server of the hub checks credentials: its tornado Application.

``GuardedApplication.start_request`` gives every request on the server an
``_Admission`` delegate, which admits it before any handler is chosen (the hub's
routes, wotpy's, the directory's, the twin's, a WebSocket handshake): it asks the
``AccessPolicy`` and routes a refused request to ``_Refused`` (401 or 403,
``WWW-Authenticate``, problem+json). A token whose answer is not remembered is
checked first, off the event loop (``TokenStore.verify_async``: scrypt on a thread of
its own): tornado waits for the delegate's ``headers_received`` before it reads the
body, so the check holds up that request only. When too many checks wait, the request
gets 503 with ``Retry-After``. An admitted request carries its ``Principal`` as
``request.wott_principal`` (the WebSocket handler reads it once per socket).
Requests to the embedded directory get the hub's in-process directory credential in
place of the client's token, which the hub has already checked.

The ``access_token`` query parameter is taken out of the request (its ``uri``,
``query`` and arguments) as soon as it is read: no handler, log line, error page or
audit entry downstream can show it (the log's record factory, ``redact.py``, catches
what is left: a token quoted in an exception, a header echoed).

The output transform restricts CORS to the configured origins off loopback (every
handler's ``Access-Control-Allow-Origin: *`` is rewritten here, not in each
handler), lets preflights allow ``Authorization``, and records in the audit trail
every request that is not a read, with the status it got, and every refusal.

The access log (``log_request``) leaves out the query (it may hold ``access_token``), cuts
the path to ``audit.MAX_TARGET`` characters, and logs answers >= 400 (which anyone can
provoke) at most ``ERROR_LINES`` a minute (``LogRate``): the log stays bounded under a flood.
"""

from __future__ import annotations

import copy
import json
import logging
import re
from collections.abc import Awaitable

import tornado.web
from tornado import httputil
from tornado.escape import parse_qs_bytes, url_unescape
from tornado.log import access_log

from .audit import AuditLog, clip
from .lograte import LogRate
from .policy import _DIRECTORY, QUERY_PARAM, AccessPolicy, Decision
from .redact import install_log_redaction
from .tokens import TooManyChecks

__all__ = ["GuardedApplication", "guard"]

log = logging.getLogger("wott_hub.security")

_UNAUDITED = frozenset({"GET", "HEAD", "OPTIONS"})
ERROR_LINES = 20
"""Access-log lines of answers >= 400 per minute at most (then one line counts the rest)."""
_SCRUB = re.compile(r"[?#].*$")


class _Refused(tornado.web.RequestHandler):
    def initialize(self, decision: Decision) -> None:
        self.decision = decision

    def prepare(self) -> None:
        d = self.decision
        self.set_status(d.status)
        if d.status == 503:
            self.set_header("Retry-After", "1")
        else:
            self.set_header("WWW-Authenticate", d.www_authenticate())
        self.set_header("Content-Type", "application/problem+json")
        self.set_header("Access-Control-Allow-Origin", "*")
        title = {401: "Unauthorized", 403: "Forbidden"}.get(d.status, "Service Unavailable")
        self.finish(json.dumps({"type": "about:blank", "title": title, "status": d.status,
                                "detail": d.reason, "instance": self.request.path}))


class _Transform(tornado.web.OutputTransform):
    def __init__(self, request: httputil.HTTPServerRequest, policy: AccessPolicy, audit: AuditLog | None):
        self.request = request
        self.policy = policy
        self.audit = audit

    def transform_first_chunk(self, status_code: int, headers: httputil.HTTPHeaders, chunk: bytes,
                              finishing: bool) -> tuple[int, httputil.HTTPHeaders, bytes]:
        req = self.request
        if "Access-Control-Allow-Origin" in headers:
            allowed = self.policy.cors_origin(req.headers.get("Origin"))
            if allowed is None:
                del headers["Access-Control-Allow-Origin"]
            else:
                headers["Access-Control-Allow-Origin"] = allowed
                if allowed != "*":
                    headers.add("Vary", "Origin")
        allow = headers.get("Access-Control-Allow-Headers")
        if allow is not None and "authorization" not in allow.lower():
            headers["Access-Control-Allow-Headers"] = allow + ", Authorization"
        if self.audit is not None and (req.method not in _UNAUDITED or status_code in (401, 403)):
            principal = getattr(req, "wott_principal", None)
            self.audit.record(principal.name if principal is not None else "-", req.method or "",
                              _SCRUB.sub("", req.path), req.remote_ip or "", status_code)
        return status_code, headers, chunk

    def transform_chunk(self, chunk: bytes, finishing: bool) -> bytes:
        return chunk


def _strip_token(request: httputil.HTTPServerRequest) -> str | None:
    """Take ``access_token`` out of ``request`` (uri, query, arguments); returns its value."""
    found = request.query_arguments.get(QUERY_PARAM)
    if not found:
        return None
    kept = [part for part in request.query.split("&")
            if part and url_unescape(part.partition("=")[0], plus=True) != QUERY_PARAM]
    request.query = "&".join(kept)
    request.uri = request.path + ("?" + request.query if request.query else "")
    request.arguments = parse_qs_bytes(request.query, keep_blank_values=True)
    request.query_arguments = copy.deepcopy(request.arguments)
    return found[0].decode("utf-8", "replace")


class _Admission(httputil.HTTPMessageDelegate):
    """One request on a guarded server: admitted (after a token check off the loop when one is
    needed), then routed by the Application like any other."""

    def __init__(self, app: GuardedApplication, server_conn: object,
                 request_conn: httputil.HTTPConnection) -> None:
        self.app = app
        self.server_conn = server_conn
        self.request_conn = request_conn
        self.delegate: httputil.HTTPMessageDelegate | None = None
        self.closed = False

    def headers_received(self, start_line: httputil.RequestStartLine | httputil.ResponseStartLine,
                         headers: httputil.HTTPHeaders) -> Awaitable[None] | None:
        assert isinstance(start_line, httputil.RequestStartLine)
        request = httputil.HTTPServerRequest(connection=self.request_conn,
                                             server_connection=self.server_conn,
                                             start_line=start_line, headers=headers)
        policy = self.app.policy
        assert policy is not None  # start_request makes an _Admission only then
        try:
            query_token = _strip_token(request)
            method = request.method or "GET"
            token = policy.to_check(method, request.path, request.headers, query_token)
            if token is not None:
                return self._check_then_route(token, request, query_token, start_line, headers)
            decision = policy.admit(method, request.path, request.headers, query_token)
        except Exception:  # a bug here must still answer the request
            log.exception("admitting %s %s failed", request.method, request.path)
            decision = Decision(503, None, "the request could not be admitted (see the hub's log)")
        return self._route(request, decision, start_line, headers)

    async def _check_then_route(self, token: str, request: httputil.HTTPServerRequest,
                                query_token: str | None, start_line: httputil.RequestStartLine,
                                headers: httputil.HTTPHeaders) -> None:
        policy = self.app.policy
        assert policy is not None and policy.store is not None  # to_check gave a token: both are there
        method = request.method or "GET"
        try:
            stored = await policy.store.verify_async(token)
            decision = policy.admit(method, request.path, request.headers, query_token, checked=(stored,))
        except TooManyChecks as e:
            decision = Decision(503, None, str(e))
        except Exception:  # a bug here must still answer the request
            log.exception("checking the token of %s %s failed", request.method, request.path)
            decision = Decision(503, None, "the request could not be admitted (see the hub's log)")
        result = self._route(request, decision, start_line, headers)
        if self.closed and self.delegate is not None:  # the client left while its token was checked
            self.delegate.on_connection_close()
        if result is not None:
            await result

    def _route(self, request: httputil.HTTPServerRequest, decision: Decision,
               start_line: httputil.RequestStartLine,
               headers: httputil.HTTPHeaders) -> Awaitable[None] | None:
        app, policy = self.app, self.app.policy
        request.wott_principal = decision.principal  # type: ignore[attr-defined]  # read by policy.allows
        if not decision.admitted:
            self.delegate = app.get_handler_delegate(request, _Refused, {"decision": decision})
        else:
            if policy is not None and policy.enforced and _DIRECTORY.match(request.path):
                request.headers["Authorization"] = f"Bearer {policy.internal_token}"
            self.delegate = app.find_handler(request)
        return self.delegate.headers_received(start_line, headers)

    def data_received(self, chunk: bytes) -> Awaitable[None] | None:
        assert self.delegate is not None  # tornado reads a body only once the headers were taken
        return self.delegate.data_received(chunk)

    def finish(self) -> None:
        assert self.delegate is not None
        self.delegate.finish()

    def on_connection_close(self) -> None:
        self.closed = True
        if self.delegate is not None:
            self.delegate.on_connection_close()


class GuardedApplication(tornado.web.Application):
    """A tornado Application that admits requests by ``policy`` before routing them."""

    policy: AccessPolicy | None = None
    audit: AuditLog | None = None
    error_log_rate: LogRate | None = None

    def start_request(self, server_conn: object,
                      request_conn: httputil.HTTPConnection) -> httputil.HTTPMessageDelegate:
        if self.policy is None:
            return super().start_request(server_conn, request_conn)
        return _Admission(self, server_conn, request_conn)

    def log_request(self, handler: tornado.web.RequestHandler) -> None:
        """tornado's access log line, with the query left out: it may hold ``access_token``."""
        if "log_function" in self.settings:
            self.settings["log_function"](handler)
            return
        status = handler.get_status()
        log_method = access_log.info if status < 400 else (
            access_log.warning if status < 500 else access_log.error)
        if status >= 400:
            if self.error_log_rate is None:
                self.error_log_rate = LogRate(access_log, ERROR_LINES, 60.0, "answers >= 400")
            if not self.error_log_rate.allow():
                return
        req = handler.request
        log_method("%d %s %s (%s) %.2fms", status, req.method, clip(req.path), req.remote_ip,
                   1000.0 * req.request_time())


def guard(app: tornado.web.Application, policy: AccessPolicy | None,
          audit: AuditLog | None = None) -> tornado.web.Application:
    """Put ``app`` (a ``GuardedApplication``) under ``policy``; transforms added once."""
    if policy is None:
        return app
    install_log_redaction()  # no secret in a log line of this process from now on (redact.py)
    if not isinstance(app, GuardedApplication):
        app.__class__ = type("Guarded" + type(app).__name__, (GuardedApplication, type(app)), {})
    assert isinstance(app, GuardedApplication)  # its class is one now
    app.policy = policy
    app.audit = audit
    # tornado calls each transform "class" with the request: a factory does as well
    app.transforms.append(lambda request: _Transform(request, policy, audit))  # type: ignore[arg-type]
    return app
