"""The hub's devices: open each (here or in a worker process), serve it, run its pipeline.

A device is a ``DeviceRuntime``: its served Thing and its ``DevicePipeline``
(``wott_hub.runtime.pipeline``). Opened in-process, the pipeline runs here as a
task and writes into the event plane; opened in a worker process (``[hub]
workers``), the pipeline runs there (``wott_hub.runtime.worker``) and the hub
keeps a pipeline without a processor, fed with the records, health and end the
worker sends (``Devices`` hears them: ``runtime.pool.WorkerEvents``).
"""

from __future__ import annotations

import asyncio
import logging
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from wott_hub.errors import Conflict
from wott_hub.plugins.model import check_device_id
from wott_hub.runtime.capabilities import action_names
from wott_hub.runtime.opening import CLOSE_TIMEOUT_S, open_driver
from wott_hub.runtime.pipeline import CONTACTS, UNAVAILABLE, DevicePipeline, initial_contacts
from wott_hub.runtime.raw import RawRecorder, RawSource
from wott_hub.servient import ServedThing, clean_td
from wott_hub.td.builder import build_tactile_td, static_property_values

if TYPE_CHECKING:
    from wott_hub.config import HubConfig
    from wott_hub.drivers.base import Driver
    from wott_hub.events.plane import EventPlane
    from wott_hub.events.record import Record
    from wott_hub.plugins.model import DeviceConfig
    from wott_hub.runtime.handle import DeviceHandle
    from wott_hub.runtime.pipeline import Report
    from wott_hub.runtime.pool import WorkerDevice, WorkerPool
    from wott_hub.tactile import DeviceDescription, FrameProcessor
    from wott_hub.tactile.raw import RawSample

    from .recording import HubHistory
    from .things import Things

__all__ = ["DeviceRuntime", "Devices"]

log = logging.getLogger("wott_hub.hub")

_HALT_MARGIN_S = 1.0
"""Beyond a driver's own ``close()`` bound: what a cancelled pipeline may take to end."""


def _consume(task: asyncio.Future[Any]) -> None:
    if not task.cancelled():
        task.exception()


@dataclass(eq=False)
class DeviceRuntime:
    """One served device: its Thing, its pipeline and, when it runs in a worker process, its proxy."""

    id: str
    family: str
    thing: ServedThing
    pipeline: DevicePipeline
    worker: WorkerDevice | None = None  # set: the pipeline runs in that worker's process
    task: asyncio.Task[None] | None = None
    config: DeviceConfig | None = None  # what it was opened from (None: Hub.add_driver); restart reopens it
    actions: dict[str, Any] = field(default_factory=dict)  # device actions' counters (device_actions.py)
    raw: RawSource | None = None  # its raw signals, read on demand (runtime/raw.py)
    recorder: asyncio.Task[None] | None = None  # its images recorded at the rate it opted in to

    @property
    def driver(self) -> DeviceHandle:
        """The device's ``Driver``, or its ``WorkerDevice`` proxy."""
        return self.pipeline.driver

    @property
    def processor(self) -> FrameProcessor | None:
        """None when a worker process processes the frames."""
        return self.pipeline.processor

    @property
    def record(self) -> bool:
        return self.thing.record

    def health_state(self) -> tuple[str, str]:
        return self.pipeline.health_state()


class Devices:
    """The running devices, the configured ones that failed to open, the worker processes; the
    ``runtime.restart.DeviceHost`` of the device actions' restarts."""

    def __init__(self, config: HubConfig, plane: EventPlane, things: Things, history: HubHistory) -> None:
        self.config = config
        self.plane = plane
        self.things = things
        self.history = history
        self.running: dict[str, DeviceRuntime] = {}
        self.failed: dict[str, str] = {}  # configured devices that could not be opened: why
        self.pool: WorkerPool | None = None  # when [hub] workers > 0
        self.live = False  # the hub is up: a worker that exits now is an error

    async def open_configured(self) -> None:
        """Open and serve every configured device (not run yet); one that fails is reported and the
        others are served."""
        from wott_hub.errors import DriverError

        cfg = self.config
        if cfg.workers > 0 and cfg.devices:
            from wott_hub.runtime.pool import WorkerPool  # multiprocessing only when it is used

            self.pool = WorkerPool(cfg.workers, self, cfg.worker_nice)
        for dcfg in cfg.devices:
            try:
                await self.add_device(dcfg, run=False)
            except (DriverError, Conflict) as e:  # one bad device must not keep the fleet down
                log.error("device %s not started: %s", dcfg.id, e)
                self.failed[dcfg.id] = str(e)
            except Exception as e:  # a description the hub cannot serve (plugin data): that device only
                log.exception("device %s not started", dcfg.id)
                self.failed[dcfg.id] = f"device {dcfg.id!r}: {type(e).__name__}: {e}"

    async def run_all(self) -> None:
        """Once history is open: attach each device to it and start its pipeline."""
        for dev in list(self.running.values()):
            await self._attach(dev)
            self._run(dev)

    async def add_device(self, dcfg: DeviceConfig, *, run: bool = True) -> DeviceRuntime:
        """Open a configured device (``wott_hub.plugins.DeviceConfig``) and serve it."""
        record = dcfg.id not in self.config.history_skip
        if self.pool is not None:  # opened in a worker process: its frames are processed there
            proxy, _family = await self.pool.open(dcfg)
            pipeline = DevicePipeline(dcfg.id, proxy, None, initial_contacts(proxy.description))
            return await self._add(proxy.description, pipeline, proxy,
                                   family=dcfg.family, record=record, run=run, config=dcfg)
        # open + prepare (e.g. a network device's mesh, read before its TD can be built), isolated
        driver = await open_driver(dcfg)
        return await self.add_driver(driver, device_id=dcfg.id, family=dcfg.family, record=record, run=run,
                                     config=dcfg)

    async def add_driver(self, driver: Driver, *, device_id: str | None = None, family: str | None = None,
                         record: bool = True, run: bool = True,
                         config: DeviceConfig | None = None) -> DeviceRuntime:
        """Serve an open driver as a device Thing and (``run``) start its pipeline here; ``config``: the
        ``DeviceConfig`` it was opened from (its ``restart`` action opens it again from that)."""
        desc = driver.description
        pipeline = DevicePipeline.of_driver(device_id or desc.id, driver)
        return await self._add(desc, pipeline, None, family=family, record=record, run=run, config=config)

    def _check_free(self, tid: str) -> None:
        check_device_id(tid, "device id")  # every binding's syntax (plugins.model), whoever opened it
        if self.things.server.things.get(tid) is not None:  # regardless of case (ThingRegistry)
            raise Conflict(f"device id {tid!r} is already served")

    async def _add(self, desc: DeviceDescription, pipeline: DevicePipeline, worker: WorkerDevice | None, *,
                   family: str | None, record: bool, run: bool,
                   config: DeviceConfig | None = None) -> DeviceRuntime:
        tid = pipeline.thing
        self._check_free(tid)
        layout = self.things.server.layout
        reopenable = config is not None  # restart opens it again from its config (here or in its worker)
        actions = action_names(pipeline.driver, reopenable=reopenable,
                               capabilities=worker.capabilities if worker is not None else None)
        raw = _raw_source(tid, pipeline, worker)
        td = build_tactile_td(desc, base=f"{layout.http_base}/", forms=layout.factory(tid),
                              context_url=layout.context_url, actions=actions,
                              raw=raw.signals if raw is not None else ())
        td["id"] = self.things.identity.device_id(tid)
        td["forms"] = layout.thing_forms(tid)
        if layout.mqtt is not None:
            layout.mqtt.add_context(td)
        clean_td(td)
        static = static_property_values(desc)
        static.pop(CONTACTS, None)
        static.pop(UNAVAILABLE, None)
        served = ServedThing.create(tid, td, static, record=record and self.config.history)
        dev = DeviceRuntime(tid, family or desc.family, served, pipeline, worker, config=config, raw=raw)
        served.raw = raw
        served.dynamic[CONTACTS] = pipeline.read_contacts
        served.dynamic[UNAVAILABLE] = pipeline.read_unavailable
        self.things.serve(served)
        self.running[tid] = dev
        if run:
            await self._attach(dev)
            self._run(dev)
        return dev

    async def _attach(self, dev: DeviceRuntime) -> None:
        await self.history.attach(dev.thing, dev.family)

    def _run(self, dev: DeviceRuntime) -> None:
        if dev.raw is not None and dev.recorder is None:  # a camera that opted in to recording its images
            recorder = RawRecorder(dev.id, dev.raw, self.plane)
            if recorder.signals:
                dev.recorder = asyncio.create_task(recorder.run(), name=f"raw-recorder:{dev.id}")
        if dev.worker is not None:  # its worker process runs it
            dev.pipeline.started()
            dev.worker.run(self.plane.trace)
            return
        dev.task = asyncio.create_task(dev.pipeline.run(self.plane, trace=self.plane.trace),
                                       name=f"device:{dev.id}")

    async def _halt(self, dev: DeviceRuntime) -> None:
        """Stop a device's pipeline and close its driver, in ``CLOSE_TIMEOUT_S`` (and a margin) at most:
        a ``close()`` that hangs, or a ``frames()`` that will not end once cancelled (a camera that never
        opens), is logged and left behind; the device is removed / the hub stops anyway."""
        recorder, dev.recorder = dev.recorder, None
        if recorder is not None:
            recorder.cancel()
            await asyncio.gather(recorder, return_exceptions=True)
        task, dev.task = dev.task, None
        if task is not None:
            task.cancel()
        waits: set[asyncio.Future[Any]] = {asyncio.ensure_future(dev.pipeline.close())}
        if task is not None:
            waits.add(task)
        _, late = await asyncio.wait(waits, timeout=CLOSE_TIMEOUT_S + _HALT_MARGIN_S)
        if task is not None and task in late:
            log.error("device %s: its driver's frames() did not end within %g s of being cancelled; "
                      "abandoned", dev.id, CLOSE_TIMEOUT_S + _HALT_MARGIN_S)
            task.add_done_callback(_consume)  # if it ever ends, its outcome is not an unhandled error

    async def remove(self, device_id: str) -> None:
        dev = self.running.pop(device_id)
        await self._halt(dev)
        self.things.unserve(device_id)

    async def stop(self) -> None:
        """Stop every pipeline and close every driver (at once, each bounded as in ``_halt``), then the
        worker processes."""
        await asyncio.gather(*(self._halt(d) for d in self.running.values()))
        if self.pool is not None:
            await self.pool.close()

    # --- runtime.restart.DeviceHost: a restart of a device in this process ------------------------

    def is_current(self, device_id: str, pipeline: DevicePipeline) -> bool:
        dev = self.running.get(device_id)
        return dev is not None and dev.pipeline is pipeline

    async def halt(self, device_id: str) -> None:
        await self._halt(self.running[device_id])

    def resume(self, device_id: str) -> None:
        self._run(self.running[device_id])

    # --- runtime.pool.WorkerEvents: devices running in worker processes -----------------------------

    def on_records(self, recs: list[Record]) -> None:
        dev = self.running.get(recs[0].thing)
        if dev is not None:
            dev.pipeline.remote_records(recs, self.plane)

    def on_health(self, reports: dict[str, Report]) -> None:
        for did, report in reports.items():
            dev = self.running.get(did)
            if dev is not None:
                dev.pipeline.remote_health(report)

    def on_ended(self, device_id: str, reason: str) -> None:
        dev = self.running.get(device_id)
        if dev is not None:
            dev.pipeline.ended(reason)

    def on_worker_exit(self, worker: int) -> None:
        if not self.live:
            return
        log.error("worker process %d exited; its devices stopped", worker)
        for dev in self.running.values():
            if dev.worker is not None and dev.worker.worker == worker:
                dev.pipeline.failed("its worker process exited")


def _raw_source(thing: str, pipeline: DevicePipeline, worker: WorkerDevice | None) -> RawSource | None:
    """The device's raw signals, sampled from its driver here or from its worker (None: it has none)."""
    if worker is not None:
        return RawSource(thing, worker.raw_signals, worker.raw_sample) if worker.raw_signals else None
    signals = pipeline.raw_signals()
    if not signals:
        return None

    async def sample(name: str) -> RawSample | None:
        return pipeline.raw_sample(name)

    return RawSource(thing, signals, sample)
