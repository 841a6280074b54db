"""The taxel array as a hub driver: serial frames in, ``TactileFrame``s out."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable
from typing import Any

import numpy as np

from wott_hub.drivers.backoff import Backoff
from wott_hub.drivers.base import Driver, DriverError, Health
from wott_hub.tactile import DeviceDescription, TactileFrame

from .compliance import Compliance
from .protocol import Counters
from .reader import SerialReader
from .simulator import TaxelSimulator

__all__ = ["TaxelDriver"]


class TaxelDriver(Driver):
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
        self._backoff = backoff
        self._opener = opener
        self._reader: SerialReader | None = None
        self._inward = -description.mesh.normals
        self.set_health(Health.disconnected, "not started")

    async def frames(self) -> AsyncIterator[TactileFrame]:
        if self._reader is not None:
            raise DriverError(f"device {self.description.id!r}: frames() is already being iterated")
        port = self.port
        if self.simulator is not None:
            port = self.simulator.start()
        assert port is not None
        self._reader = reader = SerialReader(
            port, shape=self.shape, baudrate=self.baudrate, protocol=self.protocol, counters=self.counters,
            backoff=self._backoff, opener=self._opener, on_health=self.set_health,
        )
        compliance = self.compliance
        try:
            async for t_ns, raw in reader.frames():
                self.last_seq = raw.seq
                counts = raw.values.astype(np.float64)
                yield TactileFrame(t_ns, compliance.normal_mm(counts)[:, None] * self._inward,
                                   pressure=compliance.pressure_kpa(counts))
        finally:
            reader.stop()

    async def close(self) -> None:
        if self._reader is not None:
            await self._reader.close()
        if self.simulator is not None:
            await asyncio.to_thread(self.simulator.stop)
        self.set_health(Health.disconnected, "closed")
