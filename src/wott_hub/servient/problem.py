"""Problem details (RFC 9457) for every error the hub's HTTP port answers.

One writer for all the port's handlers (the hub's routes, wotpy's routes
through the adapters, paths nobody serves), so a client always gets
``application/problem+json`` with ``status``, ``title`` and a ``detail`` that
names the offending field, Thing or affordance, never tornado's HTML page or
wotpy's ``{"error": ...}``. ``title`` carries the same text as ``detail``: the
hub's clients (the web twin, node-wot tests) read ``title``, and RFC 9457
allows any human-readable summary there.

Writing a problem never raises: a handler that failed while failing (wotpy
raising ``HTTPError`` with a message where the status belongs) still answers.
Handlers that keep tornado's default ``write_error`` (the web twin's, a method
a route does not implement: 405) are covered by ``ProblemTransform``, an
output transform of the whole Application that rewrites tornado's HTML error
page into the same problem document.
"""

from __future__ import annotations

import html
import json
import re
from http import HTTPStatus
from typing import Any

import tornado.web
from tornado import httputil

__all__ = ["MethodNotAllowed", "NotFoundHandler", "ProblemTransform", "problem_json", "write_problem"]

PROBLEM_JSON = "application/problem+json"


class MethodNotAllowed(tornado.web.HTTPError):
    """A 405 that carries its ``Allow`` header through tornado's ``send_error`` (which clears headers)."""

    def __init__(self, allow: str, reason: str) -> None:
        super().__init__(405, reason=reason)
        self.allow = allow


def problem_json(status: int, detail: str, instance: str | None = None) -> str:
    """The problem document for ``status`` and ``detail`` (and the request path, if given)."""
    body: dict[str, Any] = {"type": "about:blank", "title": detail, "status": status, "detail": detail}
    if instance is not None:
        body["instance"] = instance
    return json.dumps(body)


def _status_and_detail(handler: tornado.web.RequestHandler, status_code: Any,
                       kwargs: dict[str, Any]) -> tuple[int, str]:
    exc = kwargs.get("exc_info", (None, None, None))[1]
    status = status_code if isinstance(status_code, int) and 400 <= status_code <= 599 else 500
    detail = getattr(handler, "_reason", "") or ""
    if isinstance(exc, tornado.web.HTTPError):
        if exc.reason:
            detail = exc.reason
        elif exc.log_message and status < 500:
            detail = exc.log_message % exc.args if exc.args else exc.log_message
    if not detail or detail == "Unknown":
        try:
            detail = HTTPStatus(status).phrase
        except ValueError:
            detail = "Error"
    return status, detail


def write_problem(handler: tornado.web.RequestHandler, status_code: Any, **kwargs: Any) -> None:
    """``RequestHandler.write_error`` for the hub: a problem+json body, whatever went wrong."""
    status, detail = _status_and_detail(handler, status_code, kwargs)
    if handler._finished:
        return
    try:
        handler.set_status(status)
    except ValueError:
        handler.set_status(500)
    handler.set_header("Content-Type", PROBLEM_JSON)
    handler.set_header("Access-Control-Allow-Origin", "*")
    exc = kwargs.get("exc_info", (None, None, None))[1]
    if isinstance(exc, MethodNotAllowed):
        handler.set_header("Allow", exc.allow)
    handler.finish(problem_json(status, detail, handler.request.path))


class NotFoundHandler(tornado.web.RequestHandler):
    """The default handler of the hub's port: any path no route serves is a problem+json 404."""

    def prepare(self) -> None:
        raise tornado.web.HTTPError(404, reason=f"Nothing is served at {self.request.path!r}")

    def write_error(self, status_code: int, **kwargs: Any) -> None:
        write_problem(self, status_code, **kwargs)


_TORNADO_ERROR_PAGE = re.compile(rb"^<html><title>(\d{3}): (.*?)</title><body>")


class ProblemTransform(tornado.web.OutputTransform):
    """Rewrites tornado's default HTML error page (any handler on the port) into problem+json."""

    def __init__(self, request: httputil.HTTPServerRequest) -> None:
        super().__init__(request)
        self.path = request.path

    def transform_first_chunk(self, status_code: int, headers: httputil.HTTPHeaders, chunk: bytes,
                              finishing: bool) -> tuple[int, httputil.HTTPHeaders, bytes]:
        if status_code < 400 or not finishing or not headers.get("Content-Type", "").startswith("text/html"):
            return status_code, headers, chunk
        m = _TORNADO_ERROR_PAGE.match(chunk)
        if m is None:
            return status_code, headers, chunk
        detail = html.unescape(m.group(2).decode("utf-8", "replace"))
        body = problem_json(status_code, detail, self.path).encode()
        headers["Content-Type"] = PROBLEM_JSON
        if "Content-Length" in headers:
            headers["Content-Length"] = str(len(body))
        return status_code, headers, body
