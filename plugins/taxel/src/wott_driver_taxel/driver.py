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

What the counts mean is the ``readings``' (``readings.py``): pressure through the skin's compliance
(the project's protocols), or counts above a baseline (FlexiTac, 3D-ViTac); so are the raw signals
(``ServesRawSignals``: the last frame's grids) and what ``tare`` takes again. The first grid is
recorded in history as ``pressureGridRecorded`` events ``record_hz`` times a second when the device
opts in (``record_raw_hz``: learning exports read it, docs/learning.md of wott-hub).
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable
from typing import Any

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
from .readings import CountReadings, PressureReadings, Readings
from .simulator import TaxelSimulator

__all__ = ["QUEUE_FRAMES", "TaxelDriver"]

QUEUE_FRAMES = 256
"""Frames read but not yet processed, at most: 2.5 s at 100 frames/s (a busy hub catches up, none lost)."""


class TaxelDriver(Driver, Tareable, ServesRawSignals):
    """A rows x cols taxel array on ``port`` (or on its own simulator's pty).

    With a ``compliance``, each taxel's pressure becomes an inward displacement along the mesh
    normal; ``frame.pressure`` carries the pressure in kPa. Without one (an uncalibrated matrix),
    the node vectors are the counts above a baseline of ``baseline_frames`` frames
    (``description.node_signal`` says so). ``counters`` and ``last_seq`` (the sequence number of the
    frame just yielded) are there for diagnostics and for checking against a simulator.
    """

    def __init__(
        self,
        description: DeviceDescription,
        *,
        shape: tuple[int, int],
        compliance: Compliance | None = None,
        baseline_frames: int = 30,
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
        inward = -description.mesh.normals
        rate = float(simulator.rate_hz) if simulator is not None else 0.0
        self.readings: Readings = (PressureReadings(compliance, inward, shape, rate, record_hz)
                                   if compliance is not None
                                   else CountReadings(inward, shape, rate, baseline_frames, record_hz))
        self.raw_signals: tuple[RawSignal, ...] = self.readings.raw_signals
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
            queue_size=QUEUE_FRAMES,
        )
        readings = self.readings
        clock = self.clock
        clock.reset()
        failed = False
        try:
            async for arrival_ns, raw in reader.frames():
                self.last_seq = raw.seq
                frame = readings.frame(clock.stamp(raw.seq, arrival_ns), raw.values)
                if frame is None:  # a reading that makes no frame (the first baseline is being taken)
                    continue
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
        """Zero offsets again (drift, a preloaded skin): what that means is the readings'."""
        return self.readings.tare()

    def raw_sample(self, name: str) -> RawSample | None:
        return self.readings.raw_sample(name)

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
