"""Actions over HTTP, the one way: the hub Thing's (replay, history, fleet) and the devices'.

An action is an affordance and an async callable taking the input object and answering the
output, written as JSON, or a ``Stream`` written chunk by chunk with its own media type. The
hub Thing declares each in its TD with one POST form (``response`` in an affordance: the form's
response media type) under ``/wot/hub/actions/<name>``. A body that is not a JSON object is a
400; a ``WottHubError`` the callable raises is the problem+json status of ``errors.http_status``
with its message, which names the field at fault. An empty or ``null`` body is no input (``{}``).

A client that leaves while its action runs (a long export) ends it: the request's task is
cancelled (``on_connection_close``) and a ``Stream``'s generator closed, which cancels the work
behind it (``exports.py``); nothing is logged for it but a line at DEBUG.
"""

from __future__ import annotations

import asyncio
import copy
import json
import logging
from collections.abc import AsyncGenerator, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import tornado.iostream
import tornado.web

from wott_hub.errors import InvalidInput, WottHubError, http_status
from wott_hub.servient import HUB_THING_ID
from wott_hub.servient.http import BaseHandler
from wott_hub.types import Invoke

if TYPE_CHECKING:
    from wott_hub.servient.server import HubServer

__all__ = ["ActionHandler", "Stream", "Table", "install"]

log = logging.getLogger(__name__)

Table = Mapping[str, tuple[dict[str, Any], Invoke]]
"""An action's name -> its affordance and its ``Invoke``."""


@dataclass(frozen=True)
class Stream:
    """An output too large for one JSON document (records, an MCAP file): sent as it comes."""

    content_type: str
    chunks: AsyncGenerator[bytes | str, None]


def install(td: dict[str, Any], server: HubServer, table: Table) -> None:
    """Declare ``table``'s actions in the hub Thing's TD (before it is served) and mount their handlers."""
    base = server.layout.thing_url(HUB_THING_ID)
    actions = td.setdefault("actions", {})
    for name, (affordance, _) in table.items():
        aff = copy.deepcopy(affordance)
        response = aff.pop("response", None)
        form: dict[str, Any] = {"href": f"{base}/actions/{name}", "op": ["invokeaction"],
                                "htv:methodName": "POST", "contentType": "application/json"}
        if response:
            form["response"] = {"contentType": response}
        aff["forms"] = [form]
        actions[name] = aff
    server.add_handlers([(rf"/wot/{HUB_THING_ID}/actions/{name}", ActionHandler, {"invoke": invoke})
                         for name, (_, invoke) in table.items()])


class ActionHandler(BaseHandler):
    """POST: the action; OPTIONS: its CORS preflight. CORS headers and problem+json from ``BaseHandler``."""

    def initialize(self, invoke: Invoke) -> None:
        self.invoke = invoke
        self._task: asyncio.Task[Any] | None = None
        self._left = False

    def on_connection_close(self) -> None:
        """The client left before the answer was complete: the action's work ends with it."""
        self._left = True
        if self._task is not None and not self._task.done():
            self._task.cancel()

    def options(self, *_args: Any, **_kwargs: Any) -> None:
        self.set_header("Access-Control-Allow-Methods", "POST, OPTIONS")
        self.set_header("Access-Control-Allow-Headers", "Content-Type, Accept")
        self.set_status(204)

    async def post(self, **groups: str) -> None:
        self._task = asyncio.current_task()
        try:
            out = await self.invoke(self._input(), **groups)
            if isinstance(out, Stream):
                await self._stream(out)
                return
        except WottHubError as e:
            raise tornado.web.HTTPError(http_status(e), reason=str(e)) from None
        except tornado.iostream.StreamClosedError:
            log.debug("%s %s: the client left", self.request.method, self.request.path)
            return
        except asyncio.CancelledError:
            if not self._left:
                raise  # the hub stopping, not the client leaving
            log.debug("%s %s: the client left", self.request.method, self.request.path)
            return
        self.write_json_text(json.dumps(out))

    async def _stream(self, out: Stream) -> None:
        chunks = out.chunks
        try:
            first = True
            async for chunk in chunks:
                if first:  # the first chunk is ready (or an error raised, answered as a problem)
                    self.set_header("Content-Type", out.content_type)
                    first = False
                self.write(chunk)
                await self.flush()
            if first:
                self.set_header("Content-Type", out.content_type)
            self.finish()
        finally:
            await chunks.aclose()  # the work behind it ends now, not when the generator is collected

    def _input(self) -> dict[str, Any]:
        body = self.request.body.strip() if self.request.body else b""
        try:
            value = json.loads(body) if body else None
        except ValueError as e:
            raise InvalidInput(f"the body is not JSON: {e}") from None
        if value is None:
            return {}
        if not isinstance(value, dict):
            raise InvalidInput("the input must be a JSON object")
        return value
