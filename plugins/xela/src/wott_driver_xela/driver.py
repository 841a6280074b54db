"""One XELA sensor position as a hub driver: the server's readings in, 3-axis taxel changes out.

The node vectors are the taxels' counts less their baseline (``NodeSignal("taxelSignal")``: x, y
shear and z normal, counts), or, with ``forces``, the server's calibrated forces less theirs
(``NodeSignal("force")``, N: a contact's force is then their sum). The baseline is the mean of the
first ``baseline_messages`` readings; ``tare`` takes it again from the next ones while the old one
stays in use. Frame times are the server's cadence on the hub's clock (``FrameClock`` over its running
numbers). A reading this position cannot use (``protocol.Problem``, another model than configured, no
``calibrated`` when forces are wanted) makes the device ``degraded`` with the reason, and no frame,
until a good one comes; the connection's own state (``connection``) is the device's otherwise.

Raw signals (``ServesRawSignals``): ``taxelSignal`` (``raw`` as read, ``change`` less the baseline,
counts) and, with ``forces``, ``taxelForce`` (``force``, N, as the server calibrated it).
"""

from __future__ import annotations

from collections.abc import AsyncIterator

import numpy as np
from wott_driver_taxel.clock import FrameClock

from wott_hub.plugin_api import (
    Backoff,
    DeviceDescription,
    Driver,
    Health,
    RawSample,
    RawSignal,
    ServesRawSignals,
    TactileFrame,
    Tareable,
)

from .connection import Connection, Subscription, acquire, release
from .protocol import Problem, Reading

__all__ = ["XelaDriver"]


class XelaDriver(Driver, Tareable, ServesRawSignals):
    def __init__(self, description: DeviceDescription, *, url: str, position: int, model: str,
                 forces: bool = False, baseline_messages: int = 10, backoff: Backoff | None = None) -> None:
        super().__init__(description)
        self.url = url
        self.position = str(position)
        self.model = model
        self.forces = forces
        self.baseline_messages = baseline_messages
        self.backoff = backoff or Backoff()
        self.clock = FrameClock()
        self.baseline: np.ndarray | None = None
        self.connection: Connection | None = None
        self.problems = 0  # readings that could not be used (each with its reason, in health)
        self._taking: list[np.ndarray] = []
        self._collecting = True
        self._link: tuple[Health, str] = (Health.disconnected, "not started")
        self._problem = ""
        self._last: tuple[int, Reading, np.ndarray] | None = None  # (t_ns, reading, change)
        self._sub: Subscription | None = None
        n = description.mesh.n_nodes
        signals = [RawSignal(name, "vectors", (n, 3), unit="count", term="taxelSignal")
                   for name in ("raw", "change")]
        if forces:
            signals.append(RawSignal("force", "vectors", (n, 3), unit="N", term="taxelForce"))
        self.raw_signals = tuple(signals)
        self.set_health(Health.disconnected, "not started")

    async def frames(self) -> AsyncIterator[TactileFrame]:
        await self._leave()  # a stream abandoned rather than closed: its subscription ends first
        conn = self.connection = acquire(self.url, self.backoff)
        self._sub = sub = conn.subscribe(self.position, self._on_link)
        self.clock.reset()
        try:
            while True:
                number, arrival_ns, item = await sub.queue.get()
                vectors = self._usable(item)
                if vectors is None:
                    continue
                assert isinstance(item, Reading)
                if self._collecting:
                    self._take_baseline(vectors)
                if self.baseline is None:
                    continue
                t_ns = self.clock.stamp(number, arrival_ns)
                change = vectors - self.baseline
                self._last = (t_ns, item, change)
                yield TactileFrame(t_ns, change)
        finally:
            await self._leave(sub)

    async def _leave(self, sub: Subscription | None = None) -> None:
        """End ``sub`` (default: the current one) and give its connection back."""
        sub = sub or self._sub
        conn = self.connection
        if sub is None or conn is None or sub is not self._sub:
            return
        self._sub = None
        await release(conn, sub)

    @property
    def dropped(self) -> int:
        """Readings the hub fell too far behind to keep (the current stream's)."""
        return self._sub.dropped if self._sub is not None else 0

    def _usable(self, item: Reading | Problem) -> np.ndarray | None:
        """The reading's vectors for this device, or None with the reason in health."""
        if isinstance(item, Problem):
            reason = item.reason
        elif item.model != self.model:
            reason = (f"the server reports {item.model} at position {self.position}, this device is set up "
                      f"as {self.model}")
        elif self.forces and item.forces is None:
            reason = ("the server sends no calibrated forces: turn its calibration on, or set forces = "
                      "false to read counts")
        else:
            if self._problem:
                self._problem = ""
                self.set_health(*self._link)
            return item.forces if self.forces and item.forces is not None else item.counts
        self.problems += 1
        if reason != self._problem:
            self._problem = reason
            self.set_health(Health.degraded, reason)
        return None

    def _take_baseline(self, vectors: np.ndarray) -> None:
        self._taking.append(vectors)
        if len(self._taking) == self.baseline_messages:
            self.baseline = np.mean(self._taking, axis=0)
            self._taking, self._collecting = [], False

    def _on_link(self, state: Health, reason: str) -> None:
        """The connection's state is the device's, but for a reading problem while it is ok."""
        self._link = (state, reason)
        if state != Health.ok:
            self._problem = ""  # the link's own trouble says more
        if not self._problem:
            self.set_health(state, reason)

    def tare(self) -> str:
        self._taking, self._collecting = [], True
        return f"the mean of the next {self.baseline_messages} readings becomes each taxel's baseline"

    def raw_sample(self, name: str) -> RawSample | None:
        """The last reading's taxels, N x 3: ``raw`` counts, ``change`` (the node vectors), ``force`` (N)."""
        last = self._last
        if last is None:
            return None
        t_ns, reading, change = last
        if name == "raw":
            return RawSample(t_ns, reading.counts)
        if name == "change":
            return RawSample(t_ns, change)
        if name == "force" and self.forces and reading.forces is not None:
            return RawSample(t_ns, reading.forces)
        return None

    async def close(self) -> None:
        await self._leave()
        self.set_health(Health.disconnected, "closed")
