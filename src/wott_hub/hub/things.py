"""Serving a Thing on the hub: on the event plane and on every binding at once, or not at all.

Devices, the hub Thing, replay Things and any Thing an embedding program adds
(``Hub.expose_thing``) all go through ``serve`` and ``unserve``; the network
side hears of each through the servient's ``on_expose``/``on_remove``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from wott_hub.errors import Conflict
from wott_hub.servient import ServedThing, with_forms

if TYPE_CHECKING:
    from wott_hub.events.plane import EventPlane
    from wott_hub.servient import HubServer

    from .identity import HubIdentity
    from .recording import HubHistory

__all__ = ["Things"]


class Things:
    def __init__(self, plane: EventPlane, server: HubServer, history: HubHistory,
                 identity: HubIdentity) -> None:
        self.plane = plane
        self.server = server
        self.history = history
        self.identity = identity  # the hub's id, in every Thing id it serves (identity.py)

    def serve(self, served: ServedThing, start_after: int | None = None) -> None:
        """Put a Thing on the event plane and on every binding; nothing is left behind if it
        cannot be served (``Conflict``: its id collides with another's, in WebSocket URLs too)."""
        self.plane.add_stream(served.id, record=served.record, start_after=start_after)
        try:
            self.server.expose(served)
        except ValueError as e:
            self.plane.remove_stream(served.id)
            raise Conflict(str(e)) from None

    def unserve(self, thing_id: str) -> None:
        self.server.remove(thing_id)
        self.plane.remove_stream(thing_id)

    async def expose(self, thing_id: str, td: dict[str, Any], *, static_values: dict[str, Any] | None = None,
                     dynamic: dict[str, Callable[[], str]] | None = None, record: bool = False,
                     family: str = "") -> ServedThing:
        """Serve any Thing on the hub (forms and base are rewritten to the hub's layout).

        Its records are published with ``Hub.publish(thing_id, name, value)``;
        ``record`` keeps them in history like a device's.
        """
        td = with_forms(td, thing_id, self.server.layout)
        record = record and self.history.writer is not None
        served = ServedThing.create(thing_id, td, static_values, dynamic, record=record)
        # served first, as a device is: history records the TD the servient serves (its security written)
        self.serve(served)
        if record:
            await self.history.attach(served, family)
        return served
