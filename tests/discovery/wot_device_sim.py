"""A network tactile device that already speaks WoT, for discovery tests: it serves its own Tactile
TD over HTTP, its properties, its ``skinDeformedDetection`` event over Server-Sent Events, and
announces itself as ``_wot._tcp`` on mDNS (loopback only), like a third-party device would.

Run: ``python wot_device_sim.py --name skin-7 --host 127.0.0.2``; prints ``READY <td url>`` once
announced, withdraws (mDNS goodbye) on SIGTERM. Control endpoints for tests:

- ``POST /press`` plays a press (a real scene through the hub's ``FrameProcessor``, 60 frames/s)
  and answers with the packets it sent, as ``[{"id": ..., "packet": ...}]``;
- ``POST /outage?seconds=S`` closes every event stream and refuses new ones (503) for S seconds,
  during which ``/press`` still produces (and keeps) packets: a client resuming with
  ``Last-Event-ID`` gets them afterwards.

Event ids are microseconds since the epoch, like a wott-hub's unrecorded Things, so they keep
increasing when the simulator is restarted.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import signal
import time

from tornado.httpserver import HTTPServer
from tornado.iostream import StreamClosedError
from tornado.netutil import bind_sockets
from tornado.web import Application, RequestHandler
from zeroconf.asyncio import AsyncZeroconf

from wott_hub.discovery import Announcer
from wott_hub.examples import example_device
from wott_hub.sim.scene import Scene
from wott_hub.tactile import FrameProcessor, TactileFrame
from wott_hub.tactile.processing import processing_params
from wott_hub.td.builder import build_tactile_td, static_property_values
from wott_hub.td.forms import PREFIX

EVENT = "skinDeformedDetection"


class Device:
    """The simulated device: its description, its packets so far and its subscribers."""

    def __init__(self, shape: str) -> None:
        self.desc = example_device(shape)
        self.values = {k: json.dumps(v) for k, v in static_property_values(self.desc).items()}
        self.sent: list[tuple[int, str]] = []  # (id, packet JSON), for Last-Event-ID resume
        self.subscribers: set[asyncio.Queue] = set()
        self.refuse_until = 0.0
        self._last_id = 0

    def next_id(self) -> int:
        self._last_id = max(self._last_id + 1, time.time_ns() // 1000)
        return self._last_id

    def publish(self, packet: dict) -> dict:
        eid, data = self.next_id(), json.dumps(packet)
        self.sent.append((eid, data))
        for q in self.subscribers:
            q.put_nowait((eid, data))
        return {"id": eid, "packet": packet}

    async def press(self) -> list[dict]:
        d = self.desc
        mesh = d.mesh
        at = [float(v) for v in mesh.nodes[mesh.free_indices[len(mesh.free_indices) // 2]]]
        scene = Scene.from_dict({"scene": {"name": "press", "loop": False}, "step": [
            {"kind": "press", "at": at, "start_s": 0.0, "duration_s": 0.25, "depth_mm": 1.0,
             "radius_mm": 4.0}]})
        proc = FrameProcessor(mesh, processing_params(d))  # what the hub would use for this device
        out, t0 = [], time.time_ns()
        for k in range(int(0.35 * 60) + 1):
            t = k / 60
            res = proc.process(TactileFrame(t0 + int(t * 1e9), scene.displacement_at(t, mesh)))
            packet = res.skin_deformed_detection()
            if packet is not None:
                out.append(self.publish(packet))
            await asyncio.sleep(1 / 60)
        return out


class Handler(RequestHandler):
    def initialize(self, device: Device, td: dict) -> None:
        self.device = device
        self.td = td


class TDHandler(Handler):
    def get(self) -> None:
        self.set_header("Content-Type", "application/td+json")
        self.finish(json.dumps(self.td))


class PropertyHandler(Handler):
    def get(self, name: str) -> None:
        if name not in self.device.values:
            self.send_error(404)
            return
        self.set_header("Content-Type", "application/json")
        self.finish(self.device.values[name])


class EventsHandler(Handler):
    async def get(self) -> None:
        dev = self.device
        if time.monotonic() < dev.refuse_until:
            self.send_error(503)
            return
        self.set_header("Content-Type", "text/event-stream")
        self.set_header("Cache-Control", "no-cache")
        queue: asyncio.Queue = asyncio.Queue()
        dev.subscribers.add(queue)
        try:
            last = self.request.headers.get("Last-Event-ID")
            if last:
                for eid, data in dev.sent:
                    if eid > int(last):
                        queue.put_nowait((eid, data))
            self.write(": sim\n\n")
            await self.flush()
            while (item := await queue.get()) is not None:
                eid, data = item
                self.write(f"id: {eid}\nevent: {EVENT}\ndata: {data}\n\n")
                await self.flush()
        except StreamClosedError:
            pass
        finally:
            dev.subscribers.discard(queue)
        if not self._finished:
            with contextlib.suppress(StreamClosedError):
                self.finish()


class PressHandler(Handler):
    async def post(self) -> None:
        self.set_header("Content-Type", "application/json")
        self.finish(json.dumps(await self.device.press()))


class OutageHandler(Handler):
    def post(self) -> None:
        dev = self.device
        dev.refuse_until = time.monotonic() + float(self.get_query_argument("seconds", "1"))
        for q in dev.subscribers:
            q.put_nowait(None)
        self.finish()


async def main(args: argparse.Namespace) -> None:
    sockets = bind_sockets(0, args.host)
    port = sockets[0].getsockname()[1]
    base = f"http://{args.host}:{port}/"
    device = Device(args.shape)
    td = build_tactile_td(device.desc, base=base)  # forms: /wot/<device>/properties|events/<name>
    td["id"] = args.id
    td["title"] = args.name
    thing = f"{PREFIX}/{device.desc.id}"
    k = {"device": device, "td": td}
    server = HTTPServer(Application([
        ("/td", TDHandler, k),
        (rf"{thing}/properties/([A-Za-z]+)", PropertyHandler, k),
        (rf"{thing}/events/{EVENT}", EventsHandler, k),
        ("/press", PressHandler, k),
        ("/outage", OutageHandler, k),
    ]))
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
    for q in device.subscribers:
        q.put_nowait(None)
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
