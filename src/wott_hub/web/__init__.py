"""The digital twin in the browser: a fleet page and a live 3D skin per device.

Static HTML/JS served by the hub (``routes``). The pages talk only to the hub's
public endpoints -- the TD Directory (``/things``, ``/events``), TDs and the
forms they declare (property reads, SSE, WebSocket, the hub Thing's actions) --
so they double as a proof that a plain WoT client needs nothing more. See
docs/twin.md.
"""

from .assets import routes

__all__ = ["routes"]
