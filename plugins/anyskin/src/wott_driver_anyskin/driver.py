"""An AnySkin or ReSkin board as a hub driver: burst frames in, magnetic-field changes out.

Each sample's field (µT, each chip in its own axes) is turned into the board frame (``boards``) and
less its baseline becomes the frame's node vectors: ``NodeSignal("magneticField")``, never a
displacement. The baseline is the mean of the first ``baseline_samples`` samples (5, as the makers'
visualiser takes it); ``tare`` takes it again from the next ones while the old one stays in use, and
no frame comes out before the first. Frame times are the board's cadence (``FrameClock`` over the
samples' running index, repeats included). The link (``SerialReader``: its thread, the backoff, an
unplugged port) is the taxel plugin's.

Raw signals (``ServesRawSignals``), as the property ``magneticField``: ``raw``, the last sample as read
(each chip's axes, what the makers' readers return) and ``change``, the node vectors.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable
from typing import Any

import numpy as np
from wott_driver_taxel.clock import FrameClock
from wott_driver_taxel.reader import SerialReader

from wott_hub.plugin_api import (
    Backoff,
    DeviceDescription,
    Driver,
    DriverError,
    Health,
    HealthStatus,
    RawSample,
    RawSignal,
    ServesRawSignals,
    TactileFrame,
    Tareable,
)

from .boards import Board
from .protocol import N_MAGS, AnySkinDecoder, Counters
from .simulator import AnySkinSimulator

__all__ = ["QUEUE_SAMPLES", "AnySkinDriver"]

QUEUE_SAMPLES = 1024
"""Samples read but not yet processed, at most: 2 s at 500 samples/s (a busy hub catches up, none lost)."""


class AnySkinDriver(Driver, Tareable, ServesRawSignals):
    """Five magnetometers on ``port``; ``counters`` say what the link did (docs/skins.md)."""

    def __init__(self, description: DeviceDescription, *, board: Board, port: str | None = None,
                 simulator: AnySkinSimulator | None = None, baudrate: int = 115200, baseline_samples: int = 5,
                 backoff: Backoff | None = None, opener: Callable[[], Any] | None = None) -> None:
        super().__init__(description)
        if port is None and simulator is None:
            raise DriverError(f"device {description.id!r}: a board needs a port or a simulator")
        self.board = board
        self.port = port
        self.simulator = simulator
        self.baudrate = baudrate
        self.baseline_samples = baseline_samples
        self.counters = Counters()
        self.clock = FrameClock()
        self.baseline: np.ndarray | None = None
        self._rotations = board.rotations
        self._taking: list[np.ndarray] = []
        self._collecting = True
        self._backoff = backoff
        self._opener = opener
        self._reader: SerialReader | None = None
        self._last: tuple[int, np.ndarray, np.ndarray] | None = None  # (t_ns, raw, change)
        self.raw_signals = tuple(RawSignal(name, "vectors", (N_MAGS, 3), unit="uT", term="magneticField")
                                 for name in ("raw", "change"))
        self.set_health(Health.disconnected, "not started")

    async def frames(self) -> AsyncIterator[TactileFrame]:
        await self._retire_reader()
        port = self.simulator.start() if self.simulator is not None else self.port
        assert port is not None
        decoder = AnySkinDecoder(self.counters, joining=True)
        self._reader = reader = SerialReader(port, decoder=decoder, baudrate=self.baudrate,
                                             backoff=self._backoff, opener=self._opener,
                                             on_health=self.set_health, queue_size=QUEUE_SAMPLES)
        clock = self.clock
        clock.reset()
        try:
            async for arrival_ns, sample in reader.frames():
                board = np.einsum("kij,kj->ki", self._rotations, sample.field)
                if self._collecting:
                    self._take_baseline(board)
                if self.baseline is None:
                    continue
                t_ns = clock.stamp(sample.number, arrival_ns)
                change = board - self.baseline
                self._last = (t_ns, sample.field, change)
                yield TactileFrame(t_ns, change)
        finally:
            await self._retire_reader(reader)

    def _take_baseline(self, board: np.ndarray) -> None:
        self._taking.append(board)
        if len(self._taking) == self.baseline_samples:
            self.baseline = np.mean(self._taking, axis=0)
            self._taking, self._collecting = [], False

    def health(self) -> HealthStatus:
        """The link's health; while it is ok, the share of repeated samples when there are any (the
        board re-sent a reading: counted, not delivered) and the first baseline's progress."""
        status = super().health()
        if status.state != Health.ok:
            return status
        c = self.counters
        notes = []
        if self.baseline is None:
            notes.append(f"taking the baseline: {len(self._taking)}/{self.baseline_samples} samples")
        if c.duplicates:
            notes.append(f"{round(100 * c.duplicates / (c.duplicates + c.frames))} % of samples were "
                         "repeats of the one before (skipped)")
        return HealthStatus(status.state, "; ".join(notes), status.since_ns) if notes else status

    def tare(self) -> str:
        self._taking, self._collecting = [], True
        return f"the mean of the next {self.baseline_samples} samples becomes the baseline"

    def raw_sample(self, name: str) -> RawSample | None:
        """The last sample's field, 5 x 3 µT: as read (``raw``) or the node vectors (``change``)."""
        last = self._last
        if last is None or name not in ("raw", "change"):
            return None
        return RawSample(last[0], last[1] if name == "raw" else last[2])

    async def _retire_reader(self, reader: SerialReader | None = None) -> None:
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
