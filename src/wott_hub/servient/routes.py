"""Every route of the hub's own on its HTTP port, in the order tornado must try them.

The raw-signal routes (``raw.py``) and the binary event streams (``binary.py``) come before the
generic property and event routes of ``http.py``, whose paths would take theirs; those modules
build on ``http.py``'s handlers, so the list is assembled here, above all three.
"""

from __future__ import annotations

from typing import Any

from wott_hub.td.raw import RAW_PROPERTIES

from .binary import BinaryEventHandler, BinaryEventSocket
from .context import ServingContext
from .forms import PREFIX
from .http import routes as http_routes
from .raw import RawObserveHandler, RawPropertyHandler, RawStreamHandler

__all__ = ["routes"]


def routes(ctx: ServingContext) -> list[tuple[Any, ...]]:
    """The hub's routes, to put before wotpy's in the HTTP server's Application."""
    k = {"ctx": ctx}
    t = rf"{PREFIX}/(?P<thing_id>[^/]+)"
    raw = "|".join(sorted(RAW_PROPERTIES))
    return [
        (rf"{t}/properties/(?P<name>{raw})/stream", RawStreamHandler, k),
        (rf"{t}/properties/(?P<name>{raw})/observe", RawObserveHandler, k),
        (rf"{t}/properties/(?P<name>{raw})", RawPropertyHandler, k),
        (rf"{t}/events/(?P<name>[^/]+)/binary/ws", BinaryEventSocket, k),
        (rf"{t}/events/(?P<name>[^/]+)/binary", BinaryEventHandler, k),
        *http_routes(ctx),
    ]
