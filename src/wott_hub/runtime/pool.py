"""The hub's end of the worker processes: the pool, and a proxy for each device opened in one.

``WorkerPool`` starts ``[hub] workers`` processes (``worker.worker_main``),
opens each device in the next one still running (round robin; ``WorkerDied``
when none is, or when its worker exits before the device is open) and reads what they send
(``messages``): the answers it waits for itself (``Opened``/``OpenFailed``,
``Acted``), the rest handed to the hub (``WorkerEvents``), a batch of records
frame by frame. The hub sees a device opened in a worker through a
``WorkerDevice`` (a ``handle.DeviceHandle``): its description, its worker, the
capabilities its worker reported, the health its worker last reported.

Device actions: ``WorkerDevice.act`` sends ``Act`` and waits for its ``Acted``,
at most ``ACTION_TIMEOUT_S`` (``RESTART_TIMEOUT_S`` for a restart) and never
for a worker that has exited (``WorkerDied``). Raw signals: ``WorkerDevice.raw_sample`` sends
``Sample`` and waits for its ``Sampled`` the same way (``ACTION_TIMEOUT_S``).
"""

from __future__ import annotations

import asyncio
import contextlib
import multiprocessing as mp
import time
from typing import TYPE_CHECKING, Any, Protocol

from wott_hub import errors
from wott_hub.drivers.base import Health, HealthStatus
from wott_hub.errors import DriverError, WorkerDied, WottHubError

from .messages import (
    Act,
    Acted,
    Batch,
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
from .worker import worker_main

if TYPE_CHECKING:
    import multiprocessing.connection
    import multiprocessing.process

    from wott_hub.events.record import Record
    from wott_hub.plugins.model import DeviceConfig
    from wott_hub.tactile import DeviceDescription
    from wott_hub.tactile.raw import RawSample, RawSignal

    from .messages import ToWorker
    from .pipeline import Report

__all__ = ["ACTION_TIMEOUT_S", "RESTART_TIMEOUT_S", "WorkerDevice", "WorkerEvents", "WorkerPool"]

ACTION_TIMEOUT_S = 10.0
"""How long the hub waits for a worker to answer ``tare``/``recalibrate`` (a request, not the work)."""

RESTART_TIMEOUT_S = 60.0
"""... and ``restart`` (closing and opening a driver: a camera, a serial port, a model to load)."""

_ERRORS: dict[str, type[WottHubError]] = {
    c.__name__: c for c in (errors.Conflict, errors.DriverError, errors.NotFound, errors.InvalidInput,
                            errors.ConfigError, errors.SettingsError)}
"""The error classes a worker's answer may name; anything else is a ``DriverError``."""


class WorkerEvents(Protocol):
    """What the hub hears of its workers' devices (``hub.devices.Devices``)."""

    def on_records(self, recs: list[Record]) -> None:
        """One frame's records of one device (not yet numbered), in the order the worker made them."""
        ...

    def on_health(self, reports: dict[str, Report]) -> None:
        """Each device's pipeline report (every second)."""
        ...

    def on_ended(self, device_id: str, reason: str) -> None:
        """The device's frame stream ended."""
        ...

    def on_worker_exit(self, worker: int) -> None:
        """Worker ``worker``'s process exited: its devices stopped."""
        ...


class WorkerDevice:
    """The hub's handle on a device opened in a worker process: its description, its worker,
    the health the worker last reported. Its frames never reach the hub: records do."""

    def __init__(self, device_id: str, description: DeviceDescription, pool: WorkerPool, worker: int,
                 capabilities: tuple[str, ...] = (), raw_signals: tuple[RawSignal, ...] = ()) -> None:
        self.id = device_id
        self.description = description
        self.pool = pool
        self.worker = worker
        self.capabilities = capabilities  # the device actions its driver can do, as its worker reported
        self.raw_signals = raw_signals  # its driver's raw signals, as its worker reported
        self._health = HealthStatus.now(Health.ok)

    def health(self) -> HealthStatus:
        return self._health

    def set_health(self, state: Health, reason: str = "") -> None:
        if state != self._health.state or reason != self._health.reason:
            self._health = HealthStatus.now(state, reason)

    def run(self, trace: bool) -> None:
        self.pool.send(self.worker, Run(self.id, trace))

    async def act(self, action: str) -> tuple[str, WottHubError | None, Report | None]:
        """Have the worker do device action ``action``: (detail, error, report) (``WorkerPool.request``)."""
        timeout = RESTART_TIMEOUT_S if action == "restart" else ACTION_TIMEOUT_S
        return await self.pool.request(self.worker, self.id, action, timeout)

    async def raw_sample(self, name: str) -> RawSample | None:
        """The driver's latest sample of raw signal ``name``, from its worker (``WorkerPool.sample``)."""
        return await self.pool.sample(self.worker, self.id, name, ACTION_TIMEOUT_S)

    async def close(self) -> None:
        self.pool.send(self.worker, CloseDevice(self.id))


class WorkerPool:
    """``n`` worker processes at CPU priority ``nice`` below the hub's; what they send goes to ``events``."""

    def __init__(self, n: int, events: WorkerEvents, nice: int = 0) -> None:
        ctx = mp.get_context("spawn")  # no fork of a running event loop and its sockets
        self.events = events
        self.procs: list[mp.process.BaseProcess] = []
        self.conns: list[mp.connection.Connection] = []
        self._pending: dict[str, tuple[int, asyncio.Future[Opened]]] = {}  # device -> (worker, answer)
        self._requests: dict[int, tuple[int, asyncio.Future[Acted]]] = {}  # -> (worker, answer)
        self._samples: dict[int, tuple[int, asyncio.Future[Sampled]]] = {}  # the same, for Sample
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

    def send(self, worker: int, msg: ToWorker) -> None:
        with contextlib.suppress(OSError, ValueError):
            self.conns[worker].send(msg)

    async def open(self, cfg: DeviceConfig) -> tuple[WorkerDevice, str]:
        """Open ``cfg`` (a ``DeviceConfig``) in the next worker still running; (proxy, family), or
        ``DriverError`` (``WorkerDied`` if no worker runs, or if it exits before answering: a device
        is never left waiting for the answer of a process that is gone)."""
        live = [i for i in range(len(self.conns)) if i not in self._gone]
        if not live:
            raise WorkerDied(f"device {cfg.id!r}: every worker process has exited")
        worker = live[self._next % len(live)]
        self._next += 1
        fut: asyncio.Future[Opened] = self._loop.create_future()
        self._pending[cfg.id] = (worker, fut)
        self.send(worker, Open(cfg))
        try:
            opened = await fut
        finally:
            if self._pending.get(cfg.id) == (worker, fut):  # not answered: failed or cancelled
                del self._pending[cfg.id]
        proxy = WorkerDevice(cfg.id, opened.description, self, worker, opened.capabilities,
                             opened.raw_signals)
        return proxy, opened.family

    async def request(self, worker: int, device_id: str, action: str,
                      timeout_s: float) -> tuple[str, WottHubError | None, Report | None]:
        """Send ``Act`` and await its ``Acted``: (detail, error, report), ``error`` the worker's answer as
        its ``wott_hub.errors`` class (None: done). No answer within ``timeout_s`` raises ``DriverError``;
        a worker that exits, before or meanwhile, ``WorkerDied``."""
        if worker in self._gone:
            raise WorkerDied(f"device {device_id!r}: its worker process exited")
        self._next_request += 1
        req = self._next_request
        fut: asyncio.Future[Acted] = self._loop.create_future()
        self._requests[req] = (worker, fut)
        self.send(worker, Act(device_id, req, action))
        try:
            acted = await asyncio.wait_for(fut, timeout_s)
        except TimeoutError:
            raise DriverError(f"device {device_id!r}: its worker process did not answer {action!r} "
                              f"within {timeout_s:g} s") from None
        finally:
            self._requests.pop(req, None)
        if acted.error is None:
            return acted.detail, None, acted.report
        name, message = acted.error
        return acted.detail, _ERRORS.get(name, DriverError)(message), acted.report

    async def sample(self, worker: int, device_id: str, signal: str, timeout_s: float) -> RawSample | None:
        """Send ``Sample`` and await its ``Sampled``: the sample (None: no frame yet), or the worker's
        error as its ``wott_hub.errors`` class; ``DriverError`` after ``timeout_s``, ``WorkerDied`` as for
        ``request``."""
        import numpy as np

        from wott_hub.tactile.raw import RawSample

        if worker in self._gone:
            raise WorkerDied(f"device {device_id!r}: its worker process exited")
        self._next_request += 1
        req = self._next_request
        fut: asyncio.Future[Sampled] = self._loop.create_future()
        self._samples[req] = (worker, fut)
        self.send(worker, Sample(device_id, req, signal))
        try:
            got = await asyncio.wait_for(fut, timeout_s)
        except TimeoutError:
            raise DriverError(f"device {device_id!r}: its worker process did not answer a read of "
                              f"{signal!r} within {timeout_s:g} s") from None
        finally:
            self._samples.pop(req, None)
        if got.error is not None:
            name, message = got.error
            raise _ERRORS.get(name, DriverError)(message)
        if got.data is None:
            return None
        return RawSample(got.t_ns, np.frombuffer(got.data, np.dtype(got.dtype)).reshape(got.shape))

    def _answered(self, acted: Acted) -> None:
        entry = self._requests.get(acted.request)
        if entry is not None and not entry[1].done():
            entry[1].set_result(acted)

    def _worker_gone(self, worker: int) -> None:
        self._gone.add(worker)
        waiting: list[tuple[int, asyncio.Future[Any]]] = [
            *self._requests.values(), *self._samples.values(), *self._pending.values()]
        for w, fut in waiting:
            if w == worker and not fut.done():
                fut.set_exception(WorkerDied("the device's worker process exited before answering"))

    def _readable(self, worker: int) -> None:
        conn = self.conns[worker]
        events = self.events
        for _ in range(256):  # bounded: never hold the loop for long
            try:
                if not conn.poll():
                    return
                msg = conn.recv()
            except (EOFError, OSError):
                self._loop.remove_reader(conn.fileno())
                self._worker_gone(worker)
                events.on_worker_exit(worker)
                return
            if isinstance(msg, Batch):
                on_records = events.on_records
                for recs in msg.frames:
                    on_records(recs)
            elif isinstance(msg, HealthReports):
                events.on_health(msg.reports)
            elif isinstance(msg, Acted):
                self._answered(msg)
            elif isinstance(msg, Sampled):
                entry = self._samples.get(msg.request)
                if entry is not None and not entry[1].done():
                    entry[1].set_result(msg)
            elif isinstance(msg, Ended):
                events.on_ended(msg.device, msg.reason)
            elif isinstance(msg, Opened | OpenFailed):
                opening = self._pending.pop(msg.device, None)
                if opening is None or opening[1].done():
                    continue
                if isinstance(msg, Opened):
                    opening[1].set_result(msg)
                else:
                    opening[1].set_exception(DriverError(msg.message))

    async def close(self, timeout_s: float = 10.0) -> None:
        for i, conn in enumerate(self.conns):
            self.send(i, Close())
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
