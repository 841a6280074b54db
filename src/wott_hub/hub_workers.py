"""Device pipelines in worker processes: drivers and frame processing off the event loop.

One event loop in one process serves every subscriber; processing a deformed
frame (``FrameProcessor``: contacts, forces, actions) costs 0.2-0.6 ms, so
32 devices at 120 Hz need most of a core for processing alone, and the loop
saturates. With ``[hub] workers = N`` each device is opened in one of N worker
processes (through the plugin registry, from its ``DeviceConfig``), which runs
its driver and processor and sends the records, already JSON-encoded, to the
hub over a pipe; the hub's loop only numbers, records and fans them out.

Protocol (pickled tuples on a ``multiprocessing`` pipe):

- hub -> worker: ``("open", DeviceConfig)``, ``("run", id, trace)``, ``("close_device", id)``,
  ``("close",)``
- worker -> hub: ``("opened", id, DeviceDescription, family)``, ``("failed", id, message)``,
  ``("recs", id, [(kind, name, t_ns, data, trace), ...])``,
  ``("health", {id: (state, reason, frames, frame_errors, restarts)})``, ``("ended", id, reason)``

Trace stamps are ``perf_counter_ns`` (CLOCK_MONOTONIC: the same clock in every process).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import multiprocessing as mp
import time
from collections.abc import Callable
from typing import Any

from wott_hub.drivers.base import Driver, DriverError, Health

__all__ = ["RemoteDriver", "WorkerPool", "worker_main"]

log = logging.getLogger(__name__)


class RemoteDriver(Driver):
    """The hub-side stand-in of a driver that runs in a worker process."""

    def __init__(self, description, pool: WorkerPool, worker: int) -> None:
        super().__init__(description)
        self.pool = pool
        self.worker = worker

    def frames(self):  # frames never reach the hub's loop: records do (WorkerPool)
        raise NotImplementedError("a remote driver's frames are processed in its worker process")

    async def close(self) -> None:
        self.pool.send(self.worker, ("close_device", self.description.id))


class WorkerPool:
    def __init__(self, n: int, on_message: Callable[[tuple], None]) -> None:
        ctx = mp.get_context("spawn")  # no fork of a running event loop and its sockets
        self.on_message = on_message
        self.procs = []
        self.conns = []
        self._pending: dict[str, asyncio.Future] = {}
        self._next = 0
        self._loop = asyncio.get_running_loop()
        for i in range(n):
            parent, child = ctx.Pipe(duplex=True)
            proc = ctx.Process(target=worker_main, args=(child,), name=f"wott-hub-worker-{i}", daemon=True)
            proc.start()
            child.close()
            self.procs.append(proc)
            self.conns.append(parent)
            self._loop.add_reader(parent.fileno(), self._readable, i)

    def send(self, worker: int, msg: tuple) -> None:
        with contextlib.suppress(OSError, ValueError):
            self.conns[worker].send(msg)

    async def open(self, cfg) -> tuple[Any, str, int]:
        """Open ``cfg`` in the next worker; (description, family, worker) or DriverError."""
        worker = self._next % len(self.conns)
        self._next += 1
        fut = self._loop.create_future()
        self._pending[cfg.id] = fut
        self.send(worker, ("open", cfg))
        desc, family = await fut
        return desc, family, worker

    def _readable(self, worker: int) -> None:
        conn = self.conns[worker]
        for _ in range(256):  # bounded: never hold the loop for long
            try:
                if not conn.poll():
                    return
                msg = conn.recv()
            except (EOFError, OSError):
                self._loop.remove_reader(conn.fileno())
                self.on_message(("worker_exit", worker))
                return
            kind = msg[0]
            if kind == "opened":
                fut = self._pending.pop(msg[1], None)
                if fut is not None and not fut.done():
                    fut.set_result((msg[2], msg[3]))
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

def worker_main(conn) -> None:
    logging.basicConfig(level=logging.WARNING)
    with contextlib.suppress(KeyboardInterrupt):  # the hub handles Ctrl-C and tells us to close
        asyncio.run(_worker(conn))


class _Device:
    def __init__(self, driver, processor) -> None:
        self.driver = driver
        self.processor = processor
        self.task: asyncio.Task | None = None
        self.frames = 0
        self.frame_errors = 0
        self.restarts = 0
        self.state = "starting"
        self.reason = ""
        self._had_contacts = False  # the contact state frame_records keeps (pump.py)
        self._contacts = None
        self._contacts_json: str | None = None


async def _worker(conn) -> None:
    import signal

    from wott_hub.hub import processing_params
    from wott_hub.plugins import get_registry
    from wott_hub.pump import health_state
    from wott_hub.tactile import FrameProcessor

    with contextlib.suppress(ValueError, OSError):
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    loop = asyncio.get_running_loop()
    inbox: asyncio.Queue = asyncio.Queue()

    def readable() -> None:
        try:
            while conn.poll():
                inbox.put_nowait(conn.recv())
        except (EOFError, OSError):
            inbox.put_nowait(("close",))

    loop.add_reader(conn.fileno(), readable)
    devices: dict[str, _Device] = {}

    def send(msg: tuple) -> None:
        with contextlib.suppress(OSError, ValueError):
            conn.send(msg)

    async def health() -> None:
        while True:
            await asyncio.sleep(1.0)
            report = {}
            for did, d in devices.items():
                state, reason = health_state(d)
                report[did] = (state, reason, d.frames, d.frame_errors, d.restarts)
            send(("health", report))

    health_task = asyncio.create_task(health())
    try:
        while True:
            msg = await inbox.get()
            kind = msg[0]
            if kind == "open":
                cfg = msg[1]
                try:
                    driver = get_registry().open_device(cfg)
                    await driver.prepare()  # e.g. a network device reads its mesh first
                    desc = driver.description
                    devices[cfg.id] = _Device(driver, FrameProcessor(desc.mesh, processing_params(desc)))
                    send(("opened", cfg.id, desc, cfg.family))
                except Exception as e:  # DriverError or a plugin bug: the hub reports it
                    send(("failed", cfg.id, str(e)))
            elif kind == "run":
                d = devices.get(msg[1])
                if d is not None and d.task is None:
                    d.task = asyncio.create_task(_pump(msg[1], d, msg[2], send))
            elif kind == "close_device":
                d = devices.pop(msg[1], None)
                if d is not None:
                    await _close(d)
            elif kind == "close":
                break
    finally:
        health_task.cancel()
        for d in devices.values():
            await _close(d)


async def _close(d: _Device) -> None:
    if d.task is not None:
        d.task.cancel()
        await asyncio.gather(d.task, return_exceptions=True)
    with contextlib.suppress(Exception):
        await d.driver.close()


async def _pump(did: str, d: _Device, trace: bool, send) -> None:
    from wott_hub.pump import frame_records, pump

    def records(res, t_in: int) -> None:
        recs: list[tuple] = []
        frame_records(d, did, res, t_in, _wanted, lambda _thing, *rec: recs.append(rec))
        if recs:
            send(("recs", did, recs))

    await pump(d, did, records, trace=trace)
    send(("ended", did, d.reason))


def _wanted(_thing: str, _kind: int, _name: str) -> bool:
    """Only the hub knows who wants a record: a worker makes every one."""
    return True


def apply_health(driver: Driver, state: str, reason: str) -> None:
    """Mirror a worker's health report on the hub-side driver."""
    with contextlib.suppress(ValueError):
        driver.set_health(Health(state), reason)
