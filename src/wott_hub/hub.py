"""The hub: devices in, one servient out, every event recorded.

For each device the hub opens a driver (through the plugin registry), runs a
``FrameProcessor`` on its frames and publishes what they produce on the event
plane: ``skinDeformedDetection`` and ``actionDetection`` events and changes of
the observable ``contactInformation`` property. The plane numbers them, hands
them to the history writer and to subscribers (SSE, WebSocket, wotpy).

Work is done only for someone: a record nobody subscribes to and history does
not keep is not even built (no payload dict, no JSON). The static mesh is
encoded once when the device is exposed and never sent with events.

Lifecycle: ``start`` opens (and migrates) the database, binds the ports,
exposes the hub Thing and the devices, starts the servers; ``stop`` stops the
devices, ends every stream, writes what is queued and closes. ``serve`` wraps
both with SIGINT/SIGTERM handling for ``wott-hub run``.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import signal
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from wott_hub import hub_replay
from wott_hub.config import HubConfig
from wott_hub.drivers.base import Driver, DriverError
from wott_hub.events.plane import EventPlane
from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY, encode
from wott_hub.network import HubNetwork
from wott_hub.pump import CONTACTS, frame_records, health_state, pump, skin_deformed_json
from wott_hub.servient import HUB_THING_ID, HubServer, ServedThing, clean_td, hub_td, with_forms
from wott_hub.tactile import FrameProcessor, FrameResult
from wott_hub.tactile.processing import processing_params  # also imported from here by hub_workers
from wott_hub.td.builder import build_tactile_td, static_property_values

__all__ = ["DeviceRuntime", "Hub", "ReplayRuntime", "demo_devices", "serve", "skin_deformed_json"]

log = logging.getLogger(__name__)

_NO_CONTACTS = encode({"numOfContacts": 0, "contactLocations": [], "contactForces": []})


@dataclass(eq=False)
class DeviceRuntime:
    """One running device: its driver, processor, served Thing and counters."""

    id: str
    family: str
    driver: Driver
    processor: FrameProcessor
    thing: ServedThing
    record: bool
    task: asyncio.Task | None = None
    state: str = "starting"  # starting | running | ended | failed (else the driver's health)
    reason: str = ""
    frames: int = 0
    frame_errors: int = 0
    restarts: int = 0
    _contacts: FrameResult | None = None  # last frame's contacts, encoded only when read
    _contacts_json: str | None = _NO_CONTACTS
    _had_contacts: bool = False

    def read_contacts(self) -> str:
        if self._contacts_json is None:
            self._contacts_json = encode(self._contacts.contact_information())
        return self._contacts_json

    def health_state(self) -> tuple[str, str]:
        return health_state(self)


@dataclass(eq=False)
class ReplayRuntime:
    id: str
    source: str
    thing: ServedThing
    replayer: Any
    task: asyncio.Task | None = None
    contacts_json: str = _NO_CONTACTS
    state: str = "running"


class Hub:
    def __init__(self, config: HubConfig | None = None, *, extra_handlers: Sequence[tuple] = ()) -> None:
        self.config = cfg = config or HubConfig()
        self.plane = EventPlane(ring_size=cfg.ring_size, max_pending=cfg.max_pending)
        self.server = HubServer(self.plane, host=cfg.host, http_port=cfg.http_port, ws_port=cfg.ws_port,
                                public_host=cfg.public_host, catalogue_port=cfg.catalogue_port,
                                extra_handlers=extra_handlers)
        self.server.ctx.heartbeat_s = cfg.heartbeat_s
        self.devices: dict[str, DeviceRuntime] = {}
        self.replays: dict[str, ReplayRuntime] = {}
        self.engine = None
        self.writer = None
        self.reader = None
        self.state = "stopped"
        self.started_at = 0.0
        self._health_task: asyncio.Task | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._failed_devices: dict[str, str] = {}
        self.pool = None  # WorkerPool when [hub] workers > 0
        self.network = HubNetwork(self)  # TD directory, registrations, mDNS (src/wott_hub/network/)

    # --- lifecycle ------------------------------------------------------------------

    async def start(self) -> None:
        """Serve every TD first (the fleet is visible as soon as possible), then open the
        history database and start the devices' frame pumps."""
        cfg = self.config
        self._loop = asyncio.get_running_loop()
        self.state = "starting"
        self.started_at = time.monotonic()
        self.server.bind()
        self._expose_hub_thing()
        if cfg.workers > 0 and cfg.devices:
            from wott_hub.hub_workers import WorkerPool

            self.pool = WorkerPool(cfg.workers, self._on_worker_message)
        for dcfg in cfg.devices:
            try:
                await self.add_device(dcfg, run=False)
            except DriverError as e:  # one bad device must not keep the fleet down
                log.error("device %s not started: %s", dcfg.id, e)
                self._failed_devices[dcfg.id] = str(e)
        await self.server.start(streams_ready=False)
        if cfg.history:
            await asyncio.to_thread(self._open_history)
        for dev in list(self.devices.values()):
            await self._attach_history(dev)
            self._run(dev)
        self.server.ctx.streams_ready.set()
        self._health_task = asyncio.create_task(self._watch_health())
        await self.network.start()  # the directory opens on the history database
        self.state = "ok"

    def _open_history(self) -> None:
        from wott_hub.history import HistoryReader, HistoryWriter, create_engine, database_url, upgrade

        cfg = self.config
        self.engine = create_engine(database_url(cfg.database))
        upgrade(self.engine)
        loop = self._loop

        def committed(watermarks: dict[str, int]) -> None:
            with contextlib.suppress(RuntimeError):  # loop closed during shutdown
                loop.call_soon_threadsafe(self.plane.on_committed, watermarks)

        self.writer = HistoryWriter(self.engine, batch_max=cfg.history_batch_max,
                                    interval_s=cfg.history_batch_ms / 1000, retention=cfg.retention,
                                    on_commit=committed)
        self.reader = HistoryReader(self.engine)
        self.plane.history_sink = self.writer
        self.plane.history_source = self.reader
        self.writer.start()

    async def stop(self) -> None:
        if self.state == "stopped":
            return
        self.state = "stopping"
        await self.network.stop()
        if self._health_task is not None:
            self._health_task.cancel()
        for rt in self.replays.values():
            if rt.task is not None:
                rt.task.cancel()
        tasks = [d.task for d in self.devices.values() if d.task is not None]
        for t in tasks:
            t.cancel()
        for d in self.devices.values():
            with contextlib.suppress(Exception):
                await d.driver.close()
        await asyncio.gather(*tasks, return_exceptions=True)
        if self.pool is not None:
            await self.pool.close()
        await self.server.stop()
        if self.writer is not None:
            await asyncio.to_thread(self.writer.stop)
        if self.engine is not None:
            self.engine.dispose()
        self.state = "stopped"

    async def __aenter__(self) -> Hub:
        await self.start()
        return self

    async def __aexit__(self, *exc) -> None:
        await self.stop()

    def add_handlers(self, rules: Sequence[tuple]) -> None:
        """Mount more routes on the hub's HTTP port (the TD directory, the web twin...)."""
        self.server.add_handlers(rules)

    # --- where things are ---------------------------------------------------------------

    @property
    def http_url(self) -> str:
        return self.server.layout.http_base

    @property
    def ws_url(self) -> str | None:
        return self.server.layout.ws_base

    def td_url(self, thing_id: str) -> str:
        return self.server.td_url(thing_id)

    # --- devices --------------------------------------------------------------------

    async def add_device(self, dcfg, *, run: bool = True) -> DeviceRuntime:
        """Open a configured device (``wott_hub.plugins.DeviceConfig``) and serve it."""
        if self.pool is not None:  # opened in a worker process: its frames are processed there
            from wott_hub.hub_workers import RemoteDriver

            desc, _family, worker = await self.pool.open(dcfg)
            driver = RemoteDriver(desc, self.pool, worker)
            return await self.add_driver(driver, device_id=dcfg.id, family=dcfg.family,
                                         record=dcfg.id not in self.config.history_skip, run=run)
        from wott_hub.plugins import get_registry

        driver = get_registry().open_device(dcfg)
        await driver.prepare()  # e.g. a network device's mesh, read before its TD can be built
        return await self.add_driver(driver, device_id=dcfg.id, family=dcfg.family,
                                     record=dcfg.id not in self.config.history_skip, run=run)

    async def add_driver(self, driver: Driver, *, device_id: str | None = None, family: str | None = None,
                         record: bool = True, run: bool = True) -> DeviceRuntime:
        """Serve an open driver as a device Thing and (``run``) start pumping its frames."""
        desc = driver.description
        tid = device_id or desc.id
        if tid in self.server.things.by_id:
            raise DriverError(f"device id {tid!r} is already served")
        layout = self.server.layout
        td = build_tactile_td(desc, base=f"{layout.http_base}/", forms=layout.factory(tid),
                              context_url=layout.context_url)
        td["id"] = f"urn:wott-hub:device:{tid}"
        td["forms"] = layout.thing_forms(tid)
        clean_td(td)
        static = static_property_values(desc)
        static.pop(CONTACTS, None)
        record = record and self.config.history
        served = ServedThing.create(tid, td, static, record=record)
        remote = self.pool is not None and getattr(driver, "pool", None) is self.pool
        processor = None if remote else FrameProcessor(desc.mesh, processing_params(desc))
        dev = DeviceRuntime(tid, family or desc.family, driver, processor, served, record)
        served.dynamic[CONTACTS] = dev.read_contacts
        self._serve(served)
        self.devices[tid] = dev
        if run:
            await self._attach_history(dev)
            self._run(dev)
        return dev

    async def _attach_history(self, dev: DeviceRuntime) -> None:
        """Record the device's TD and continue its sequence where history says (before any record)."""
        st = self.plane.stream(dev.id)
        if not dev.record or self.writer is None:
            st.record = dev.record = dev.thing.record = False
            return
        st.seq = st.committed = await self._register(dev.thing, dev.family)

    async def _register(self, served: ServedThing, family: str) -> int:
        """Record the Thing's TD and static values (the texts already encoded for serving); returns
        the last seq it may have used."""
        return await asyncio.to_thread(
            self.writer.register_thing, served.id, title=served.title, family=family,
            td=served.td_bytes().decode(), static_values=served.static_json())

    def _serve(self, served: ServedThing, start_after: int | None = None) -> None:
        """Put a Thing on the event plane and on every binding; nothing is left behind if it
        cannot be served (e.g. its id collides with another's in WebSocket URLs)."""
        self.plane.add_stream(served.id, record=served.record, start_after=start_after)
        try:
            self.server.expose(served)
        except ValueError as e:
            self.plane.remove_stream(served.id)
            raise DriverError(str(e)) from None

    def _unserve(self, thing_id: str) -> None:
        self.server.remove(thing_id)
        self.plane.remove_stream(thing_id)

    def _run(self, dev: DeviceRuntime) -> None:
        if dev.processor is None:  # a worker process runs it
            dev.state = "running"
            self.pool.send(dev.driver.worker, ("run", dev.id, self.plane.trace))
            return
        dev.task = asyncio.create_task(self._pump(dev), name=f"device:{dev.id}")

    def _on_worker_message(self, msg: tuple) -> None:
        """Records, health and ends of devices running in worker processes."""
        kind = msg[0]
        if kind == "recs":
            dev = self.devices.get(msg[1])
            if dev is None:
                return
            plane, tid = self.plane, dev.id
            dev.frames += 1
            for rkind, name, t_ns, data, trace in msg[2]:
                if rkind == KIND_PROPERTY and name == CONTACTS:
                    dev._contacts_json = data
                if plane.wants(tid, rkind, name):
                    plane.publish(tid, rkind, name, t_ns, data, trace)
        elif kind == "health":
            from wott_hub.hub_workers import apply_health

            for did, (state, reason, frames, errors, restarts) in msg[1].items():
                dev = self.devices.get(did)
                if dev is None:
                    continue
                dev.frames, dev.frame_errors, dev.restarts = frames, errors, restarts
                if state in ("ended", "failed"):
                    dev.state, dev.reason = state, reason
                else:
                    dev.state = "running"
                    apply_health(dev.driver, state, reason)
        elif kind == "ended":
            dev = self.devices.get(msg[1])
            if dev is not None:
                dev.state, dev.reason = "ended", msg[2]
        elif kind == "worker_exit" and self.state == "ok":
            log.error("worker process %d exited; its devices stopped", msg[1])
            for dev in self.devices.values():
                if getattr(dev.driver, "worker", None) == msg[1]:
                    dev.state, dev.reason = "failed", "its worker process exited"

    async def remove_device(self, device_id: str) -> None:
        dev = self.devices.pop(device_id)
        if dev.task is not None:
            dev.task.cancel()
        with contextlib.suppress(Exception):
            await dev.driver.close()
        if dev.task is not None:
            await asyncio.gather(dev.task, return_exceptions=True)
        self._unserve(device_id)

    async def _pump(self, dev: DeviceRuntime) -> None:
        """Frames in, records out; a driver that raises is restarted with backoff."""
        tid, wants, publish = dev.id, self.plane.wants, self.plane.publish

        def sink(res: FrameResult, t_in: int) -> None:
            frame_records(dev, tid, res, t_in, wants, publish)

        await pump(dev, tid, sink, trace=self.plane.trace)

    # --- other Things -------------------------------------------------------------------

    async def expose_thing(self, thing_id: str, td: dict[str, Any], *, static_values: dict | None = None,
                           dynamic: dict | None = None, record: bool = False,
                           family: str = "") -> ServedThing:
        """Serve any Thing on the hub (forms and base are rewritten to the hub's layout).

        Its records are published with ``hub.plane.publish(thing_id, ...)``;
        ``record`` keeps them in history like a device's.
        """
        td = with_forms(td, thing_id, self.server.layout)
        record = record and self.writer is not None
        served = ServedThing.create(thing_id, td, static_values, dynamic, record=record)
        start_after = await self._register(served, family) if record else None
        self._serve(served, start_after)
        return served

    # --- replay ---------------------------------------------------------------------

    async def add_replay(self, device_id: str, *, t_from_ns: int | None = None, t_to_ns: int | None = None,
                         speed: float = 1.0, loop: bool = False, thing_id: str | None = None,
                         names: list[str] | None = None) -> ReplayRuntime:
        """Expose a replay Thing re-emitting ``device_id``'s recorded range as live records.

        The replay Thing has the recorded device's TD (title "... (replay)", id
        ``replay-<device>``) and static values; its records get their own
        sequence and are not recorded again.
        """
        from wott_hub.history import Replayer

        if self.reader is None:
            raise DriverError("replay needs the history database (history = true)")
        info = await asyncio.to_thread(self.reader.thing_info, device_id)
        if info is None or info["td"] is None:
            raise DriverError(f"no recorded device {device_id!r} in {self.config.database}")
        tid = thing_id or f"replay-{device_id}"
        td = with_forms(info["td"], tid, self.server.layout)
        td["id"] = f"urn:wott-hub:replay:{device_id}"
        td["title"] = f"{info['title']} (replay)"
        td["description"] = f"Replay of the recorded device {device_id!r} at {speed:g}x."
        static = {k: v for k, v in info["static_values"].items() if k != CONTACTS}
        served = ServedThing.create(tid, td, static, record=False)
        replayer = Replayer(self.reader, device_id, t_from_ns=t_from_ns, t_to_ns=t_to_ns, speed=speed,
                            loop=loop, names=names)
        rt = ReplayRuntime(tid, device_id, served, replayer)
        served.dynamic[CONTACTS] = lambda: rt.contacts_json
        try:
            self._serve(served)
        except DriverError as e:  # the id is taken: bad input (400 from the replay action), not "no history"
            raise ValueError(str(e)) from None
        self.replays[tid] = rt
        return rt

    def start_replay(self, rt: ReplayRuntime) -> asyncio.Task:
        plane = self.plane

        def emit(kind: int, name: str, t_ns: int, data: str) -> None:
            if kind == KIND_PROPERTY and name == CONTACTS:
                rt.contacts_json = data
            plane.publish(rt.id, kind, name, t_ns, data)

        async def run() -> None:
            try:
                await rt.replayer.run(emit)
            finally:
                rt.state = "ended"

        rt.task = asyncio.create_task(run(), name=f"replay:{rt.id}")
        return rt.task

    # --- the hub Thing ----------------------------------------------------------------

    def _expose_hub_thing(self) -> None:
        td = hub_td(self.config.name, self.server.layout)
        hub_replay.install(self, td)  # the replay/stopReplay actions (src/wott_hub/hub_replay.py)
        self._serve(ServedThing.create(HUB_THING_ID, td, record=False, dynamic={
            "devices": lambda: encode(self.devices_summary()),
            "health": lambda: encode(self.health()),
            "eventCounters": lambda: encode(self.counters()),
        }))

    def devices_summary(self) -> list[dict[str, Any]]:
        out = []
        for d in self.devices.values():
            state, _ = d.health_state()
            out.append({"id": d.id, "title": d.thing.title, "family": d.family, "td": self.td_url(d.id),
                        "state": state, "recorded": d.record})
        for r in self.replays.values():
            out.append({"id": r.id, "title": r.thing.title, "family": "replay", "td": self.td_url(r.id),
                        "state": r.state if r.state == "ended" else "ok", "recorded": False})
        return out

    def health(self) -> dict[str, Any]:
        devices = {}
        for d in self.devices.values():
            state, reason = d.health_state()
            devices[d.id] = {"state": state, "reason": reason, "frames": d.frames,
                             "frameErrors": d.frame_errors, "restarts": d.restarts}
        for did, err in self._failed_devices.items():
            devices.setdefault(did, {"state": "failed", "reason": err})
        worst = "ok"
        if any(v["state"] not in ("ok", "ended") for v in devices.values()):
            worst = "degraded"
        history: dict[str, Any] = {"enabled": self.writer is not None}
        if self.writer is not None:
            history.update(queued=self.writer.queue_depth, errors=self.writer.errors,
                           lastError=self.writer.last_error, database=str(self.engine.url))
        return {"state": worst if self.state == "ok" else self.state,
                "uptimeSeconds": round(time.monotonic() - self.started_at, 3),
                "devices": devices, "history": history}

    def counters(self) -> dict[str, Any]:
        history = {}
        if self.writer is not None:
            w = self.writer
            history = {"written": w.written, "queued": w.queue_depth, "dropped": w.dropped,
                       "batches": w.batches, "lastBatchMs": round(w.last_batch_s * 1000, 3)}
        return {"things": self.plane.counters(), "history": history,
                "overflowDisconnects": self.plane.overflow_disconnects}

    async def _watch_health(self, every_s: float = 1.0) -> None:
        memo: dict[str, tuple[str, str]] = {}
        while True:
            changed = False
            for d in list(self.devices.values()):
                now = d.health_state()
                if memo.get(d.id) != now:
                    if d.id in memo or now[0] != "ok":
                        self.plane.publish(HUB_THING_ID, KIND_EVENT, "healthChange", time.time_ns(), encode(
                            {"device": d.id, "state": now[0], "reason": now[1], "timeStamp": time.time_ns()}))
                    memo[d.id] = now
                    changed = True
            if changed and self.plane.wants(HUB_THING_ID, KIND_PROPERTY, "health"):
                self.plane.publish(HUB_THING_ID, KIND_PROPERTY, "health", time.time_ns(),
                                   encode(self.health()))
            await asyncio.sleep(every_s)

    # --- printing -------------------------------------------------------------------

    def describe(self) -> dict[str, Any]:
        """Where everything is: for ``wott-hub run`` to print and scripts to read."""
        return {
            "http": self.http_url,
            "websocket": self.ws_url,
            "catalogue": f"{self.http_url}/wot",
            "hub": self.td_url(HUB_THING_ID),
            "devices": {d.id: self.td_url(d.id) for d in self.devices.values()},
            "replays": {r.id: self.td_url(r.id) for r in self.replays.values()},
            "failed": dict(self._failed_devices),
            "database": str(self.engine.url) if self.engine is not None else None,
            **self.network.describe(),
        }


def demo_devices() -> list[Any]:
    """The demo fleet: each installed plugin's simulated devices (``wott_hub_demo_devices``).

    With no plugin contributing any, the built-in ``scene`` family plays a
    looping scene (press, slide, tap, pinch) on each example skin, so
    ``wott-hub run`` always shows live devices.
    """
    from wott_hub.plugins import DeviceConfig, get_registry

    found = get_registry().demo_devices()
    if found:
        return found
    from wott_hub.examples import example_device

    out = []
    for shape in ("barrel", "flat", "cylinder"):
        mesh = example_device(shape).mesh
        out.append(DeviceConfig(f"scene-{shape}", "scene", {
            "title": f"{shape} skin (scene)", "shape": shape, "loop": True, "step": _demo_steps(mesh)}))
    return out


def _demo_steps(mesh) -> list[dict[str, Any]]:
    """A looping scene on ``mesh``: press, slide, tap and pinch on free nodes around its middle."""
    free = mesh.free_indices
    pts = mesh.nodes[free]
    centre = pts.mean(axis=0)
    order = free[((pts - centre) ** 2).sum(axis=1).argsort()]
    scale = float(max(pts.max(axis=0) - pts.min(axis=0)))
    radius = max(scale / 12, 2.0)
    depth = min(2.0, radius / 2)

    def at(i: int) -> list[float]:
        return [round(float(v), 3) for v in mesh.nodes[order[min(i, len(order) - 1)]]]

    far = len(order) // 3
    return [
        {"kind": "press", "at": at(0), "start_s": 0.5, "duration_s": 1.0, "depth_mm": depth,
         "radius_mm": radius},
        {"kind": "slide", "at": at(far), "to": at(0), "start_s": 2.0, "duration_s": 1.5,
         "depth_mm": depth * 0.8, "radius_mm": radius, "shear_mm": depth / 4},
        {"kind": "tap", "at": at(far // 2), "start_s": 4.0, "depth_mm": depth, "radius_mm": radius},
        {"kind": "pinch", "at": at(far), "to": at(2 * far), "start_s": 4.8, "duration_s": 1.0,
         "depth_mm": depth, "radius_mm": radius, "approach_mm": radius},
    ]


async def serve(config: HubConfig, *, ready: Callable[[Hub], None] | None = None,
                stop: asyncio.Event | None = None, extra_handlers: Sequence[tuple] = ()) -> Hub:
    """Run a hub until SIGINT/SIGTERM (or ``stop``), then shut it down cleanly."""
    stop = stop or asyncio.Event()
    loop = asyncio.get_running_loop()
    installed = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError, RuntimeError):
            loop.add_signal_handler(sig, stop.set)
            installed.append(sig)
    if config.demo and not config.devices:
        from dataclasses import replace

        config = replace(config, devices=tuple(demo_devices()))
    hub = Hub(config, extra_handlers=extra_handlers)
    try:
        await hub.start()
        if ready is not None:
            ready(hub)
        await stop.wait()
    finally:
        for sig in installed:
            loop.remove_signal_handler(sig)
        await hub.stop()
    return hub
