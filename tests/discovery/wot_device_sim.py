"""A network tactile device that already speaks WoT, for discovery tests: it serves its own TD
over HTTP and announces itself as ``_wot._tcp`` on mDNS (loopback only), like a third-party
device would. Run: ``python wot_device_sim.py --name skin-7 --host 127.0.0.2``; prints
``READY <td url>`` once announced, withdraws (mDNS goodbye) on SIGTERM.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import signal

from tornado.httpserver import HTTPServer
from tornado.netutil import bind_sockets
from tornado.web import Application, RequestHandler
from zeroconf.asyncio import AsyncZeroconf

from wott_hub.discovery import Announcer
from wott_hub.examples import example_device
from wott_hub.td.builder import build_tactile_td


class TDHandler(RequestHandler):
    def initialize(self, td: dict) -> None:
        self.td = td

    def get(self) -> None:
        self.set_header("Content-Type", "application/td+json")
        self.finish(json.dumps(self.td))


async def main(args: argparse.Namespace) -> None:
    sockets = bind_sockets(0, args.host)
    port = sockets[0].getsockname()[1]
    base = f"http://{args.host}:{port}/"
    td = build_tactile_td(example_device(args.shape), base=base)
    td["id"] = args.id
    td["title"] = args.name
    server = HTTPServer(Application([("/td", TDHandler, {"td": td})]))
    server.add_sockets(sockets)
    aiozc = AsyncZeroconf(interfaces=["127.0.0.1"])
    announcer = Announcer(aiozc, addresses=[args.host])
    await announcer.announce_thing(args.name, port, "/td")
    print(f"READY {base}td", flush=True)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    await stop.wait()
    await announcer.close()
    await aiozc.async_close()
    server.stop()


if __name__ == "__main__":
    p = argparse.ArgumentParser()
    p.add_argument("--name", default="skin-7")
    p.add_argument("--id", default="urn:example:wot-skin-7")
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--shape", default="flat")
    asyncio.run(main(p.parse_args()))
