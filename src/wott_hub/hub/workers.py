"""Device pipelines in worker processes: drivers and frame processing off the event loop.

One event loop in one process serves every subscriber; processing a deformed
frame (``FrameProcessor``: contacts, forces, actions) costs 0.2-0.6 ms, so
32 devices at 120 Hz need most of a core for processing alone, and the loop
saturates. With ``[hub] workers = N`` each device is opened in one of N worker
processes (through the plugin registry, from its ``DeviceConfig``), which runs
its ``DevicePipeline`` into a ``PipeSink`` that sends the records, already
JSON-encoded, to the hub over a pipe; the hub's loop only numbers, records and
fans them out. The hub sees such a device through a ``WorkerDevice`` proxy.

A worker batches its records: the frames its devices made in one loop tick go out together
(``Outbox``), in one message the hub reads in one go; a tick longer than ``FLUSH_S`` sends
its batch once its first frame has waited that long. One message per frame cost each side a
pickle, a write or read and a wake-up per frame (~55 µs of the worker's time and ~70 µs of the
hub's at 32 devices x 120 Hz; batched, ~30 µs each). Any other message flushes the waiting
records first: a device's records, and its ``ended``, a health report or an ``acted`` after
them, keep their order.

A worker runs at a lower CPU priority than the hub (``[hub] worker_nice``, 10 by default): on a
machine with no spare core the kernel then runs the hub's loop (numbering, history, the
subscribers' sockets) as soon as it has work, and the workers take what is left. At the same
priority, a worker that had the core kept the hub's records waiting for tens of ms (docs/hub.md,
"Worker processes").

Protocol (pickled tuples on a ``multiprocessing`` pipe):

- hub -> worker: ``("open", DeviceConfig)``, ``("run", id, trace)``, ``("close_device", id)``,
  ``("act", id, request, action)``, ``("close",)``
- worker -> hub: ``("opened", id, DeviceDescription, family, capabilities)``, ``("failed", id, message)``,
  ``("recs", [(id, [(kind, name, t_ns, data, trace, skin), ...]), ...])`` (one entry per frame, in
  the order they were made; ``skin``: None or a ``SkinArrays`` as (int64 ids, float64 intensity)
  bytes, ``SkinArrays.to_wire``; the hub hands each frame on as ``("recs", id, records)`` with a
  ``SkinArrays``),
  ``("health", {id: (state, reason, frames, frame_errors, restarts)})``, ``("ended", id, reason)``,
  ``("acted", request, detail, error, report)``

Device actions (``hub.device_actions``) on a device in a worker: ``capabilities`` are the
actions its driver can do (``pipeline.driver_capabilities``: ``"tare"``, ``"recalibrate"``),
so its TD declares what it would declare in the hub's process (and ``restart``). ``act``
asks for one (``"tare"``, ``"recalibrate"``, ``"restart"``; ``request``: a number the hub
picks); the worker answers ``acted`` with the same ``request``: ``detail`` (the driver's
sentence) and ``error`` None, or ``error`` = (name of a ``wott_hub.errors`` class, message);
``report`` is the pipeline's health tuple right after, so the hub shows the effect at once.
A ``restart`` in a worker is the in-process one: the pipeline is kept (its counters), the
driver closed and opened again from its ``DeviceConfig``; if it cannot be opened the device
reports ``failed`` and the worker retries it with the pipeline's backoff. The hub gives up
waiting after a timeout (``WorkerPool.request``) and on a worker that exits.

Trace stamps are ``perf_counter_ns`` (CLOCK_MONOTONIC: the same clock in every process).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import multiprocessing as mp
import os
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from wott_hub import errors
from wott_hub.drivers.base import Health, HealthStatus
from wott_hub.errors import DriverError, WottHubError
from wott_hub.events.record import SkinArrays
from wott_hub.tactile import DeviceDescription

from .pipeline import DevicePipeline, driver_capabilities, open_driver, restart_backoff

if TYPE_CHECKING:
    import multiprocessing.connection
    import multiprocessing.process

    from wott_hub.plugins.model import DeviceConfig

__all__ = ["ACTION_TIMEOUT_S", "FLUSH_S", "RESTART_TIMEOUT_S", "Outbox", "PipeSink", "WorkerDevice",
           "WorkerPool", "worker_main"]

log = logging.getLogger("wott_hub.hub")

ACTION_TIMEOUT_S = 10.0
"""How long the hub waits for a worker to answer ``tare``/``recalibrate`` (a request, not the work)."""

RESTART_TIMEOUT_S = 60.0
"""... and ``restart`` (closing and opening a driver: a camera, a serial port, a model to load)."""

FLUSH_S = 0.001
"""How long a frame's records wait at most for the others of their batch while the worker's loop is
busy (``Outbox``): the latency a batch adds, against the per-message cost it saves."""

Report = tuple[str, str, int, int, int]
"""A pipeline's health as a worker reports it: (state, reason, frames, frame_errors, restarts)."""

_ERRORS: dict[str, type[WottHubError]] = {
    c.__name__: c for c in (errors.Conflict, errors.DriverError, errors.NotFound, errors.InvalidInput)}
"""The error classes a worker's answer may name; anything else is a ``DriverError``."""


class WorkerDevice:
    """The hub's handle on a device opened in a worker process: its description, its worker,
    the health the worker last reported. Its frames never reach the hub: records do."""

    def __init__(self, device_id: str, description: DeviceDescription, pool: WorkerPool, worker: int,
                 capabilities: tuple[str, ...] = ()) -> None:
        self.id = device_id
        self.description = description
        self.pool = pool
        self.worker = worker
        self.capabilities = capabilities  # the device actions its driver can do, as its worker reported
        self._health = HealthStatus.now(Health.ok)

    def health(self) -> HealthStatus:
        return self._health

    def set_health(self, state: Health, reason: str = "") -> None:
        if state != self._health.state or reason != self._health.reason:
            self._health = HealthStatus.now(state, reason)

    def mirror(self, state: str, reason: str) -> None:
        """The driver's health as its worker reported it."""
        with contextlib.suppress(ValueError):
            self.set_health(Health(state), reason)

    def run(self, trace: bool) -> None:
        self.pool.send(self.worker, ("run", self.id, trace))

    async def act(self, action: str) -> tuple[str, WottHubError | None, Report | None]:
        """Have the worker do device action ``action``: (detail, error, report) (``WorkerPool.request``)."""
        timeout = RESTART_TIMEOUT_S if action == "restart" else ACTION_TIMEOUT_S
        return await self.pool.request(self.worker, self.id, action, timeout)

    async def close(self) -> None:
        self.pool.send(self.worker, ("close_device", self.id))


class WorkerPool:
    def __init__(self, n: int, on_message: Callable[[tuple[Any, ...]], None], nice: int = 0) -> None:
        ctx = mp.get_context("spawn")  # no fork of a running event loop and its sockets
        self.on_message = on_message
        self.procs: list[mp.process.BaseProcess] = []
        self.conns: list[mp.connection.Connection] = []
        self._pending: dict[str, asyncio.Future[tuple[DeviceDescription, str, tuple[str, ...]]]] = {}
        self._requests: dict[int, tuple[int, asyncio.Future[tuple[Any, ...]]]] = {}  # -> (worker, answer)
        self._next = 0
        self._next_request = 0
        self._gone: set[int] = set()  # workers whose process exited: a request fails at once
        self._loop = asyncio.get_running_loop()
        for i in range(n):
            parent, child = ctx.Pipe(duplex=True)
            proc = ctx.Process(target=worker_main, args=(child, nice), name=f"wott-hub-worker-{i}",
                               daemon=True)
            proc.start()
            child.close()
            self.procs.append(proc)
            self.conns.append(parent)
            self._loop.add_reader(parent.fileno(), self._readable, i)

    def send(self, worker: int, msg: tuple[Any, ...]) -> None:
        with contextlib.suppress(OSError, ValueError):
            self.conns[worker].send(msg)

    async def open(self, cfg: DeviceConfig) -> tuple[WorkerDevice, str]:
        """Open ``cfg`` (a ``DeviceConfig``) in the next worker; (proxy, family) or DriverError."""
        worker = self._next % len(self.conns)
        self._next += 1
        fut = self._loop.create_future()
        self._pending[cfg.id] = fut
        self.send(worker, ("open", cfg))
        desc, family, capabilities = await fut
        return WorkerDevice(cfg.id, desc, self, worker, capabilities), family

    async def request(self, worker: int, device_id: str, action: str,
                      timeout_s: float) -> tuple[str, WottHubError | None, Report | None]:
        """Send ``("act", ...)`` and await its ``acted``: (detail, error, report), ``error`` the worker's
        answer as its ``wott_hub.errors`` class (None: done). No answer within ``timeout_s``, or a worker
        that exits first, raises ``DriverError``."""
        if worker in self._gone:
            raise DriverError(f"device {device_id!r}: its worker process exited")
        self._next_request += 1
        req = self._next_request
        fut: asyncio.Future[tuple[Any, ...]] = self._loop.create_future()
        self._requests[req] = (worker, fut)
        self.send(worker, ("act", device_id, req, action))
        try:
            detail, error, report = await asyncio.wait_for(fut, timeout_s)
        except TimeoutError:
            raise DriverError(f"device {device_id!r}: its worker process did not answer {action!r} "
                              f"within {timeout_s:g} s") from None
        finally:
            self._requests.pop(req, None)
        if error is None:
            return detail, None, report
        name, message = error
        return detail, _ERRORS.get(name, DriverError)(message), report

    def _answered(self, msg: tuple[Any, ...]) -> None:
        entry = self._requests.get(msg[1])
        if entry is not None and not entry[1].done():
            entry[1].set_result(msg[2:5])

    def _worker_gone(self, worker: int) -> None:
        self._gone.add(worker)
        for w, fut in list(self._requests.values()):
            if w == worker and not fut.done():
                fut.set_exception(DriverError("the device's worker process exited before answering"))

    def _readable(self, worker: int) -> None:
        conn = self.conns[worker]
        for _ in range(256):  # bounded: never hold the loop for long
            try:
                if not conn.poll():
                    return
                msg = conn.recv()
            except (EOFError, OSError):
                self._loop.remove_reader(conn.fileno())
                self._worker_gone(worker)
                self.on_message(("worker_exit", worker))
                return
            kind = msg[0]
            if kind == "recs":
                on_message = self.on_message
                for thing, recs in msg[1]:
                    on_message(("recs", thing, [r if r[5] is None else (*r[:5], SkinArrays.from_wire(r[5]))
                                                for r in recs]))
            elif kind == "acted":
                self._answered(msg)
            elif kind == "opened":
                fut = self._pending.pop(msg[1], None)
                if fut is not None and not fut.done():
                    fut.set_result((msg[2], msg[3], msg[4]))
            elif kind == "failed" and msg[1] in self._pending:
                fut = self._pending.pop(msg[1])
                if not fut.done():
                    fut.set_exception(DriverError(msg[2]))
            else:
                self.on_message(msg)

    async def close(self, timeout_s: float = 10.0) -> None:
        for i, conn in enumerate(self.conns):
            self.send(i, ("close",))
            with contextlib.suppress(ValueError, OSError):
                self._loop.remove_reader(conn.fileno())
        deadline = time.monotonic() + timeout_s
        for proc in self.procs:
            while proc.is_alive() and time.monotonic() < deadline:
                await asyncio.sleep(0.02)
            if proc.is_alive():
                proc.terminate()
        for conn in self.conns:
            conn.close()


# --- the worker process ---------------------------------------------------------------

class Outbox:
    """The worker's side of the pipe: records of every device batched, everything else in order after them.

    A batch goes out on the next loop tick, with the frames of every device that ran
    in this one, or as soon as a frame finds its first one ``flush_s`` old (a tick
    running many devices can take longer than that). No timer: a worker woken to send
    waits for a core on a loaded host. ``send`` flushes first.
    """

    __slots__ = ("_conn", "_first", "_frames", "_handle", "_loop", "flush_s")

    def __init__(self, conn: mp.connection.Connection, flush_s: float = FLUSH_S) -> None:
        self._conn = conn
        self._loop = asyncio.get_running_loop()
        self._frames: list[tuple[str, list[tuple[Any, ...]]]] = []
        self._handle: asyncio.Handle | None = None
        self._first = 0.0  # when the first frame of the batch came
        self.flush_s = flush_s

    def frame(self, thing: str, recs: list[tuple[Any, ...]]) -> None:
        """One frame's records of device ``thing``, sent with the next batch."""
        self._frames.append((thing, recs))
        if self._handle is None:
            self._first = time.monotonic()
            self._handle = self._loop.call_soon(self.flush)
        elif time.monotonic() - self._first >= self.flush_s:
            self.flush()

    def flush(self) -> None:
        if self._handle is not None:
            self._handle.cancel()
            self._handle = None
        if self._frames:
            frames, self._frames = self._frames, []
            self._put(("recs", frames))

    def send(self, msg: tuple[Any, ...]) -> None:
        self.flush()
        self._put(msg)

    def _put(self, msg: tuple[Any, ...]) -> None:
        with contextlib.suppress(OSError, ValueError):  # the hub has gone: it will tell us to close, or not
            self._conn.send(msg)


class PipeSink:
    """The record sink of a pipeline in a worker: it wants every record (only the hub knows who
    wants one) and hands each frame's records to the worker's ``Outbox``."""

    __slots__ = ("_outbox", "_recs", "thing")

    def __init__(self, thing: str, outbox: Outbox) -> None:
        self.thing = thing
        self._outbox = outbox
        self._recs: list[tuple[Any, ...]] = []

    def wants(self, _thing: str, _kind: int, _name: str) -> bool:
        return True

    def publish(self, _thing: str, kind: int, name: str, t_ns: int, data: str,
                trace: dict[str, int] | None = None, skin: SkinArrays | None = None) -> None:
        self._recs.append((kind, name, t_ns, data, trace, None if skin is None else skin.to_wire()))

    def frame_done(self) -> None:
        if self._recs:
            self._outbox.frame(self.thing, self._recs)
            self._recs = []


def worker_main(conn: mp.connection.Connection, nice: int = 0) -> None:
    """A worker process: ``nice`` lowers its CPU priority below the hub's (``[hub] worker_nice``)."""
    logging.basicConfig(level=logging.WARNING)
    if nice:
        os.nice(nice)
    with contextlib.suppress(KeyboardInterrupt):  # the hub handles Ctrl-C and tells us to close
        asyncio.run(_worker(conn))


class _Running:
    """A device in this worker: its pipeline, the task running it, what a ``restart`` needs."""

    def __init__(self, cfg: DeviceConfig, pipeline: DevicePipeline) -> None:
        self.cfg = cfg
        self.pipeline = pipeline
        self.task: asyncio.Task[None] | None = None
        self.trace = False
        self.reopening: asyncio.Task[None] | None = None  # retrying a driver that a restart could not open
        self.restarting = False


async def _worker(conn: mp.connection.Connection) -> None:
    import signal

    from wott_hub.plugins.isolation import Guard
    from wott_hub.tactile import FrameProcessor
    from wott_hub.tactile.processing import processing_params

    with contextlib.suppress(ValueError, OSError):
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    loop = asyncio.get_running_loop()
    inbox: asyncio.Queue[tuple[Any, ...]] = asyncio.Queue()

    def readable() -> None:
        try:
            while conn.poll():
                inbox.put_nowait(conn.recv())
        except (EOFError, OSError):
            inbox.put_nowait(("close",))

    loop.add_reader(conn.fileno(), readable)
    devices: dict[str, _Running] = {}
    acting: set[asyncio.Task[None]] = set()
    out = Outbox(conn)

    async def health() -> None:
        guard = Guard("worker health report", logger=log)  # the loop outlives any one report
        while True:
            await asyncio.sleep(1.0)
            guard.call("report", lambda: out.send(("health", {did: d.pipeline.report()
                                                          for did, d in list(devices.items())})))

    health_task = asyncio.create_task(health())
    try:
        while True:
            msg = await inbox.get()
            kind = msg[0]
            if kind == "open":
                cfg = msg[1]
                try:
                    driver = await open_driver(cfg)  # isolated like the hub's (pipeline.open_driver)
                    desc = driver.description
                    processor = FrameProcessor(desc.mesh, processing_params(desc))
                    devices[cfg.id] = _Running(cfg, DevicePipeline(cfg.id, driver, processor))
                    out.send(("opened", cfg.id, desc, cfg.family, driver_capabilities(driver)))
                except Exception as e:  # a DriverError (or a processor refusing the mesh): the hub reports it
                    out.send(("failed", cfg.id, str(e)))
            elif kind == "run":
                d = devices.get(msg[1])
                if d is not None and d.task is None:
                    d.trace = msg[2]
                    d.task = asyncio.create_task(_run(d.pipeline, d.trace, out))
            elif kind == "act":  # a task: a restart must not hold up the other devices' messages
                task = asyncio.create_task(_act(devices, msg[1], msg[2], msg[3], out))
                acting.add(task)
                task.add_done_callback(acting.discard)
            elif kind == "close_device":
                d = devices.pop(msg[1], None)
                if d is not None:
                    await _close(d)
            elif kind == "close":
                break
    finally:
        health_task.cancel()
        for t in list(acting):
            t.cancel()
        for d in devices.values():
            await _close(d)
        out.flush()  # the records made before the close


async def _close(d: _Running) -> None:
    if d.reopening is not None:
        d.reopening.cancel()
    if d.task is not None:
        d.task.cancel()
        await asyncio.gather(d.task, return_exceptions=True)
    await d.pipeline.close()


async def _run(pipeline: DevicePipeline, trace: bool, out: Outbox) -> None:
    sink = PipeSink(pipeline.thing, out)
    await pipeline.run(sink, trace=trace, frame_done=sink.frame_done)
    out.send(("ended", pipeline.thing, pipeline.reason))


# --- device actions in the worker (the hub's side: hub.device_actions) ----------------------

async def _act(devices: dict[str, _Running], device_id: str, req: int, action: str,
               out: Outbox) -> None:
    """Do ``action`` on ``device_id`` and answer ``("acted", req, detail, error, report)``."""
    d = devices.get(device_id)
    detail, error = "", None
    try:
        if d is None:
            raise errors.NotFound(f"no device {device_id!r} in this worker process")
        if action == "restart":
            detail = await _restart(devices, d, out)
        else:
            detail = d.pipeline.request(action)
    except WottHubError as e:
        error = (type(e).__name__, str(e))
    except Exception as e:  # a bug here must still answer, or the hub waits for its timeout
        log.exception("device %s: %s", device_id, action)
        error = ("DriverError", f"device {device_id!r}: {action} raised {type(e).__name__}: {e}")
    out.send(("acted", req, detail, error, d.pipeline.report() if d is not None else None))


async def _restart(devices: dict[str, _Running], d: _Running, out: Outbox) -> str:
    """The in-process restart (``DeviceActions.restart``) where the driver is: same pipeline, new driver."""
    if d.restarting:
        raise errors.Conflict(f"device {d.cfg.id!r} is being restarted already")
    d.restarting = True
    try:
        if d.reopening is not None:
            d.reopening.cancel()
            d.reopening = None
        task, d.task = d.task, None
        if task is not None:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)
        await d.pipeline.close()
        d.pipeline.restarts += 1
        d.pipeline.state, d.pipeline.reason = "starting", "restarting on request"
        try:
            driver = await open_driver(d.cfg)
        except DriverError as e:
            d.pipeline.state, d.pipeline.reason = "failed", str(e)
            d.reopening = asyncio.create_task(_reopen(devices, d, str(e), out))
            raise
        await _resume(devices, d, driver, out)
    finally:
        d.restarting = False
    return "driver closed and opened again; the stream continues"


async def _resume(devices: dict[str, _Running], d: _Running, driver: Any,
                  out: Outbox) -> None:
    """Run ``d`` on ``driver``; one with another mesh than the served one is closed (``failed``, Conflict)."""
    try:
        d.pipeline.reopened(driver)
    except errors.Conflict as e:
        d.pipeline.driver = driver
        await d.pipeline.close()
        d.pipeline.state, d.pipeline.reason = "failed", str(e)
        raise
    if devices.get(d.cfg.id) is d:
        d.task = asyncio.create_task(_run(d.pipeline, d.trace, out))


async def _reopen(devices: dict[str, _Running], d: _Running, reason: str,
                  out: Outbox) -> None:
    """Open ``d`` again with the pipeline's backoff until it opens or is closed (as in the hub's process)."""
    backoff = restart_backoff()
    while True:
        delay = backoff.next_delay()
        d.pipeline.reason = f"{reason} (retry {backoff.attempts} in {delay:.1f} s)"
        await asyncio.sleep(delay)
        try:
            driver = await open_driver(d.cfg)
        except DriverError as e:
            reason = str(e)
            continue
        if devices.get(d.cfg.id) is not d:  # closed meanwhile
            await driver.close()
            return
        with contextlib.suppress(errors.Conflict):  # failed, with the reason
            await _resume(devices, d, driver, out)
        d.reopening = None
        return
