"""A worker process: device pipelines off the hub's event loop (``[hub] workers``).

One event loop in one process serves every subscriber; processing a deformed
frame (``FrameProcessor``: contacts, forces, actions) costs 0.2-0.6 ms, so
32 devices at 120 Hz need most of a core for processing alone, and the loop
saturates. With ``[hub] workers = N`` each device is opened in one of N worker
processes (through the plugin registry, from its ``DeviceConfig``), which runs
its ``DevicePipeline`` into a ``PipeSink`` that sends the records, already
JSON-encoded, to the hub over a pipe (``outbox``); the hub's loop only numbers,
records and fans them out. The hub's end is ``pool``; the messages, ``messages``.

A worker runs at a lower CPU priority than the hub (``[hub] worker_nice``, 10 by default): on a
machine with no spare core the kernel then runs the hub's loop (numbering, history, the
subscribers' sockets) as soon as it has work, and the workers take what is left. At the same
priority, a worker that had the core kept the hub's records waiting for tens of ms (docs/hub.md,
"Worker processes").

Device actions (``hub.device_actions`` in the hub) on a device here: the
capabilities reported in ``Opened`` are its driver's, so its TD declares what it
would declare in the hub's process (and ``restart``). A ``restart`` here is the
hub's own (``restart.Restarts``): the pipeline is kept (its counters), the driver
closed and opened again from its ``DeviceConfig``; if it cannot be opened the
device reports ``failed`` and is retried here with the restart backoff.

Trace stamps are ``perf_counter_ns`` (CLOCK_MONOTONIC: the same clock in every process).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
from typing import TYPE_CHECKING

from wott_hub import errors
from wott_hub.errors import WottHubError
from wott_hub.plugins.isolation import Guard

from .capabilities import driver_capabilities
from .messages import (
    Act,
    Acted,
    Close,
    CloseDevice,
    Ended,
    HealthReports,
    Open,
    Opened,
    OpenFailed,
    Run,
    Sample,
    Sampled,
)
from .opening import open_driver
from .outbox import Outbox, PipeSink
from .pipeline import DevicePipeline
from .restart import Restarts

if TYPE_CHECKING:
    import multiprocessing.connection

    from wott_hub.plugins.model import DeviceConfig

    from .messages import ToWorker

__all__ = ["worker_main"]

log = logging.getLogger("wott_hub.hub")


def worker_main(conn: multiprocessing.connection.Connection, nice: int = 0) -> None:
    """A worker process: ``nice`` lowers its CPU priority below the hub's (``[hub] worker_nice``)."""
    logging.basicConfig(level=logging.WARNING)
    if nice:
        os.nice(nice)
    with contextlib.suppress(KeyboardInterrupt):  # the hub handles Ctrl-C and tells us to close
        asyncio.run(_serve(conn))


async def _serve(conn: multiprocessing.connection.Connection) -> None:
    """Do what the hub asks until it says ``Close`` (or its end of the pipe is gone)."""
    import signal

    with contextlib.suppress(ValueError, OSError):
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    loop = asyncio.get_running_loop()
    inbox: asyncio.Queue[ToWorker] = asyncio.Queue()

    def readable() -> None:
        try:
            while conn.poll():
                inbox.put_nowait(conn.recv())
        except (EOFError, OSError):
            inbox.put_nowait(Close())

    loop.add_reader(conn.fileno(), readable)
    out = Outbox(conn)
    devices = _Devices(out)
    acting: set[asyncio.Task[None]] = set()
    health_task = asyncio.create_task(devices.report_health())
    try:
        while True:
            msg = await inbox.get()
            if isinstance(msg, Open):
                await devices.open(msg.config)
            elif isinstance(msg, Run):
                devices.run(msg.device, msg.trace)
            elif isinstance(msg, Act):  # a task: a restart must not hold up the other devices' messages
                task = asyncio.create_task(devices.act(msg))
                acting.add(task)
                task.add_done_callback(acting.discard)
            elif isinstance(msg, Sample):
                devices.sample(msg)
            elif isinstance(msg, CloseDevice):
                await devices.close(msg.device)
            elif isinstance(msg, Close):
                break
    finally:
        health_task.cancel()
        for t in list(acting):
            t.cancel()
        await devices.close_all()
        out.flush()  # the records made before the close


class _Device:
    """A device in this worker: its pipeline, the task running it, what a ``restart`` needs."""

    __slots__ = ("config", "pipeline", "task", "trace")

    def __init__(self, config: DeviceConfig, pipeline: DevicePipeline) -> None:
        self.config = config
        self.pipeline = pipeline
        self.task: asyncio.Task[None] | None = None
        self.trace = False


class _Devices:
    """This worker's devices (the ``restart.DeviceHost`` of its restarts)."""

    def __init__(self, out: Outbox) -> None:
        self.out = out
        self.by_id: dict[str, _Device] = {}
        self.restarts = Restarts(self)

    async def open(self, cfg: DeviceConfig) -> None:
        try:
            driver = await open_driver(cfg)  # isolated like the hub's (opening.open_driver)
            pipeline = DevicePipeline.of_driver(cfg.id, driver)
            self.by_id[cfg.id] = _Device(cfg, pipeline)
            self.out.send(Opened(cfg.id, driver.description, cfg.family, driver_capabilities(driver),
                                 pipeline.raw_signals()))
        except Exception as e:  # a DriverError (or a processor refusing the mesh): the hub reports it
            self.out.send(OpenFailed(cfg.id, str(e)))

    def run(self, device_id: str, trace: bool) -> None:
        d = self.by_id.get(device_id)
        if d is not None and d.task is None:
            d.trace = trace
            d.task = asyncio.create_task(self._run(d))

    async def _run(self, d: _Device) -> None:
        pipeline = d.pipeline
        await pipeline.run(PipeSink(pipeline.thing, self.out), trace=d.trace)
        self.out.send(Ended(pipeline.thing, pipeline.reason))

    async def close(self, device_id: str) -> None:
        self.restarts.cancel(device_id)
        if device_id in self.by_id:
            await self.halt(device_id)
            del self.by_id[device_id]

    async def close_all(self) -> None:
        await self.restarts.stop()
        for device_id in list(self.by_id):
            await self.halt(device_id)

    async def report_health(self) -> None:
        """Every second, each device's pipeline report; the loop outlives any one report that fails."""
        guard = Guard("worker health report", logger=log)
        while True:
            await asyncio.sleep(1.0)
            guard.call("report", lambda: self.out.send(HealthReports(
                {did: d.pipeline.report() for did, d in list(self.by_id.items())})))

    # --- restart.DeviceHost ----------------------------------------------------------------------

    def is_current(self, device_id: str, pipeline: DevicePipeline) -> bool:
        d = self.by_id.get(device_id)
        return d is not None and d.pipeline is pipeline

    async def halt(self, device_id: str) -> None:
        d = self.by_id[device_id]
        task, d.task = d.task, None
        if task is not None:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)
        await d.pipeline.close()

    def resume(self, device_id: str) -> None:
        d = self.by_id[device_id]
        d.task = asyncio.create_task(self._run(d))

    # --- raw signals (the hub's side: runtime.raw) ----------------------------------------------------

    def sample(self, msg: Sample) -> None:
        """Answer ``Sampled``: the driver's latest sample of ``msg.signal`` as bytes, or the error."""
        d = self.by_id.get(msg.device)
        try:
            if d is None:
                raise errors.NotFound(f"no device {msg.device!r} in this worker process")
            sample = d.pipeline.raw_sample(msg.signal)
        except WottHubError as e:
            self.out.send(Sampled(msg.request, 0, "", (), None, (type(e).__name__, str(e))))
            return
        if sample is None:
            self.out.send(Sampled(msg.request, 0, "", (), None, None))
            return
        array = sample.array
        self.out.send(Sampled(msg.request, sample.t_ns, array.dtype.str, tuple(array.shape),
                              array.tobytes(), None))  # tobytes: a C-order copy of any view

    # --- device actions (the hub's side: hub.device_actions) ---------------------------------------

    async def act(self, msg: Act) -> None:
        """Do ``msg.action`` on ``msg.device`` and answer ``Acted``."""
        device_id, action = msg.device, msg.action
        d = self.by_id.get(device_id)
        detail, error = "", None
        try:
            if d is None:
                raise errors.NotFound(f"no device {device_id!r} in this worker process")
            if action == "restart":
                detail = await self.restarts.restart(device_id, d.pipeline, d.config)
            else:
                detail = d.pipeline.request(action)
        except WottHubError as e:
            error = (type(e).__name__, str(e))
        except Exception as e:  # a bug here must still answer, or the hub waits for its timeout
            log.exception("device %s: %s", device_id, action)
            error = ("DriverError", f"device {device_id!r}: {action} raised {type(e).__name__}: {e}")
        self.out.send(Acted(msg.request, detail, error, d.pipeline.report() if d is not None else None))
