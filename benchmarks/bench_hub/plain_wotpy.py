"""Plain wotpy, the anchor every group compares with: its servient and a small TD for it."""

from __future__ import annotations

__all__ = ["plain_servient", "plain_td"]


def plain_td(title: str, port_http: int) -> dict:
    """A small TD for plain wotpy (the full Tactile TD takes minutes to expose there)."""
    from wott_hub.td.vocabulary import EVENTS, PROPERTIES

    return {"@context": "https://www.w3.org/2019/wot/td/v1", "title": title, "id": f"urn:plain:{title}",
            "security": "nosec_sc", "securityDefinitions": {"nosec_sc": {"scheme": "nosec"}},
            "properties": {"contactInformation": dict(PROPERTIES["contactInformation"])},
            "events": {k: dict(v) for k, v in EVENTS.items()}}


async def plain_servient(n: int, full_tactile: bool = False):
    from wotpy.protocols.http.server import HTTPServer
    from wotpy.protocols.ws.server import WebsocketServer
    from wotpy.wot.servient import Servient

    from ._hub_internals import Prebound

    class Http(Prebound, HTTPServer):  # only the port binding: wotpy's own code otherwise
        async def start(self, servient=None):
            self._servient = servient
            self._server = self._serve(self.app, self._ssl_context)

    class Ws(Prebound, WebsocketServer):
        async def start(self, servient=None):
            self._servient = servient
            self._server = self._serve(self.app, self._ssl_context)

    http, ws = Http(port=0), Ws(port=0)
    http.bind()
    ws.bind()
    servient = Servient(hostname="127.0.0.1", catalogue_port=None)
    servient.add_server(http)
    servient.add_server(ws)
    wot = await servient.start()
    return servient, wot, http, ws
