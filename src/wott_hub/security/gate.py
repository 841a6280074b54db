"""The one place a server of the hub checks credentials: its tornado Application.

``GuardedApplication.find_handler`` runs for every request before any handler is
chosen (the hub's routes, wotpy's, the directory's, the twin's, a WebSocket
handshake), asks the ``AccessPolicy``, and routes a refused request to ``_Refused``
(401 or 403, ``WWW-Authenticate``, problem+json). An admitted request carries its
``Principal`` as ``request.wott_principal`` (the WebSocket handler reads it once per
socket). Requests to the embedded directory get the hub's in-process directory
credential in place of the client's token, which the hub has already checked.

The output transform restricts CORS to the configured origins off loopback (every
handler's ``Access-Control-Allow-Origin: *`` is rewritten here, not in each
handler), lets preflights allow ``Authorization``, and records in the audit trail
every request that is not a read, with the status it got, and every refusal.

The access log (``log_request``) leaves out the query (it may hold ``access_token``), cuts
the path to ``audit.MAX_TARGET`` characters, and logs answers >= 400 (which anyone can
provoke) at most ``ERROR_LINES`` a minute (``LogRate``): the log stays bounded under a flood.
"""

from __future__ import annotations

import json
import re
from typing import Any

import tornado.web
from tornado import httputil
from tornado.log import access_log

from .audit import AuditLog, clip
from .lograte import LogRate
from .policy import _DIRECTORY, QUERY_PARAM, AccessPolicy, Decision

__all__ = ["GuardedApplication", "guard"]

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
        self.set_header("WWW-Authenticate", d.www_authenticate())
        self.set_header("Content-Type", "application/problem+json")
        self.set_header("Access-Control-Allow-Origin", "*")
        title = "Unauthorized" if d.status == 401 else "Forbidden"
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


class GuardedApplication(tornado.web.Application):
    """A tornado Application that admits requests by ``policy`` before routing them."""

    policy: AccessPolicy | None = None
    audit: AuditLog | None = None
    error_log_rate: LogRate | None = None

    def find_handler(self, request: httputil.HTTPServerRequest,
                     **kwargs: Any) -> tornado.web._HandlerDelegate:
        policy = self.policy
        if policy is not None:
            query = request.query_arguments.get(QUERY_PARAM)
            d = policy.admit(request.method or "GET", request.path, request.headers,
                             query[0].decode("utf-8", "replace") if query else None)
            request.wott_principal = d.principal  # type: ignore[attr-defined]  # read by policy.allows
            if not d.admitted:
                return self.get_handler_delegate(request, _Refused, {"decision": d})
            if policy.enforced and _DIRECTORY.match(request.path):
                request.headers["Authorization"] = f"Bearer {policy.internal_token}"
        return super().find_handler(request, **kwargs)


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
    if not isinstance(app, GuardedApplication):
        app.__class__ = type("Guarded" + type(app).__name__, (GuardedApplication, type(app)), {})
    assert isinstance(app, GuardedApplication)  # its class is one now
    app.policy = policy
    app.audit = audit
    # tornado calls each transform "class" with the request: a factory does as well
    app.transforms.append(lambda request: _Transform(request, policy, audit))  # type: ignore[arg-type]
    return app
