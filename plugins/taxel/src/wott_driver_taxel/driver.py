"""The taxel array as a hub driver: serial frames in, ``TactileFrame``s out.

``frames()`` is restartable: the hub calls it again after any exception (a
frame that fails the ``TactileFrame`` check, a bug), so each call owns a fresh
``SerialReader`` and the previous one is always stopped and joined first, even
when its generator was abandoned rather than closed. The exception that ended
a stream stays in ``health()`` (``frames() failed: ...``) and, after the
restart, as a suffix of the link's health until a frame gets through again:
the cause is never replaced by a symptom of the restart.

Frame times are the board's cadence on the hub's clock (``FrameClock``: its
sequence numbers against the arrival times, fitted), not the arrival times
themselves, which bunch and stretch with the reads; each ``frames()`` call starts
a new line.

Raw signal (``ServesRawSignals``): the pressure grid, rows x cols kPa, the last frame's
(a reference to the array the frame carries, reshaped as a view when read); recorded in history as
``pressureGridRecorded`` events ``record_hz`` times a second when the device opts in
(``record_raw_hz``: learning exports read it, docs/learning.md of wott-hub).
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable
from typing import Any

import numpy as np

from wott_hub.plugin_api import (
    Backoff,
    DeviceDescription,
    Driver,
    DriverError,
    Health,
    RawSample,
    RawSignal,
    ServesRawSignals,
    TactileFrame,
    Tareable,
)

from .clock import FrameClock
from .compliance import Compliance
from .protocol import Counters
from .reader import SerialReader
from .simulator import TaxelSimulator

__all__ = ["TaxelDriver"]


class TaxelDriver(Driver, Tareable, ServesRawSignals):
    """A rows x cols taxel array on ``port`` (or on its own simulator's pty).

    Each taxel's pressure becomes an inward displacement along the mesh
    normal through ``compliance``; ``frame.pressure`` carries the pressure in
    kPa. ``counters`` and ``last_seq`` (the sequence number of the frame just
    yielded) are there for diagnostics and for checking against a simulator.
    """

    def __init__(
        self,
        description: DeviceDescription,
        *,
        shape: tuple[int, int],
        compliance: Compliance,
        port: str | None = None,
        baudrate: int = 921600,
        protocol: str = "binary",
        simulator: TaxelSimulator | None = None,
        backoff: Backoff | None = None,
        opener: Callable[[], Any] | None = None,
        record_hz: float = 0.0,
    ) -> None:
        super().__init__(description)
        if port is None and simulator is None:
            raise DriverError(f"device {description.id!r}: a taxel array needs a port or a simulator")
        if shape[0] * shape[1] != description.mesh.n_nodes:
            raise DriverError(f"device {description.id!r}: {shape[0]} x {shape[1]} taxels but the mesh has "
                              f"{description.mesh.n_nodes} nodes")
        self.shape = shape
        self.compliance = compliance
        self.port = port
        self.baudrate = baudrate
        self.protocol = protocol
        self.simulator = simulator
        self.counters = Counters()
        self.last_seq: int | None = None
        # the board's period, until measured: the simulator's rate, unknown for a real board
        self.clock = FrameClock(1.0 / simulator.rate_hz if simulator is not None else None)
        self._backoff = backoff
        self._opener = opener
        self._reader: SerialReader | None = None
        self._failure = ""  # the exception that ended the last stream, until a frame gets through
        self._link_health: tuple[Health, str] = (Health.disconnected, "not started")
        self._inward = -description.mesh.normals
        self._zero: np.ndarray | None = None  # counts at rest after a tare, subtracted from every frame
        self._tare_next = False
        rate = float(simulator.rate_hz) if simulator is not None else 0.0
        self.raw_signals = (RawSignal("pressure", "grid", shape, unit="kPa", rate_hz=rate,
                                      record_hz=record_hz),)
        self._pressure: tuple[int, np.ndarray] | None = None  # the last frame's (t_ns, kPa per taxel)
        self.set_health(Health.disconnected, "not started")

    async def frames(self) -> AsyncIterator[TactileFrame]:
        await self._retire_reader()  # a previous stream that ended abnormally: its port is released
        port = self.port
        if self.simulator is not None:
            port = self.simulator.start()
        assert port is not None
        self._reader = reader = SerialReader(
            port, shape=self.shape, baudrate=self.baudrate, protocol=self.protocol, counters=self.counters,
            backoff=self._backoff, opener=self._opener, on_health=self._on_link_health,
        )
        compliance = self.compliance
        clock = self.clock
        clock.reset()
        failed = False
        try:
            async for arrival_ns, raw in reader.frames():
                self.last_seq = raw.seq
                t_ns = clock.stamp(raw.seq, arrival_ns)
                counts = raw.values.astype(np.float64)
                if self._tare_next:  # this frame's readings are the new zero
                    self._zero, self._tare_next = counts.copy(), False
                if self._zero is not None:
                    counts = np.maximum(counts - self._zero, 0.0)
                frame = TactileFrame(t_ns, compliance.normal_mm(counts)[:, None] * self._inward,
                                     pressure=compliance.pressure_kpa(counts))
                self._pressure = (t_ns, frame.pressure)  # type: ignore[assignment]  # set just above
                if self._failure:
                    self._failure = ""
                    self.set_health(*self._link_health)
                yield frame
        except Exception as e:
            failed, self._failure = True, f"{type(e).__name__}: {e}"
            raise
        finally:
            await self._retire_reader(reader)
            if failed:  # after the join: the stopping thread's last report must not hide the cause
                self.set_health(Health.disconnected, f"frames() failed: {self._failure}")

    def tare(self) -> str:
        """Zero offsets: the next frame's readings become every taxel's zero (drift, a preloaded skin)."""
        self._tare_next = True
        return "the next frame's readings are each taxel's new zero"

    def raw_sample(self, name: str) -> RawSample | None:
        """The pressure grid of the last frame, rows x cols kPa (``name`` ``"pressure"``)."""
        last = self._pressure
        if name != "pressure" or last is None:
            return None
        return RawSample(last[0], last[1].reshape(self.shape))

    def _on_link_health(self, state: Health, reason: str) -> None:
        """The reader's health (from its thread), with the cause of the last failure while it stands."""
        self._link_health = (state, reason)
        failure = self._failure
        if failure and state != Health.ok:
            reason = f"{reason} (restarted after {failure})" if reason else f"restarted after {failure}"
        self.set_health(state, reason)

    async def _retire_reader(self, reader: SerialReader | None = None) -> None:
        """Stop and join ``reader`` (default: the current one) and forget it if it is the current one."""
        reader = reader or self._reader
        if reader is None:
            return
        if reader is self._reader:
            self._reader = None
        await reader.close()

    async def close(self) -> None:
        await self._retire_reader()
        if self.simulator is not None:
            await asyncio.to_thread(self.simulator.stop)
        self.set_health(Health.disconnected, "closed")
