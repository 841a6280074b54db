"""A driver that plays a scripted ``Scene`` on a device at a fixed frame rate.

It yields the scene's ground truth (no raw signal, no camera, no model), so the
whole hub path -- processing, event plane, history, SSE -- runs with no
hardware and with a known answer. The plugin registry exposes it as the
built-in family ``scene``; the hub's tests and benchmarks use it directly.

Timing: frame ``k`` is due at ``start + k / rate_hz`` on the monotonic clock.
A consumer slower than the rate makes the driver skip the missed ticks (a real
camera drops frames too) rather than burst to catch up; skipped ticks are
counted and reported as ``degraded`` health while it lasts. Frame timestamps
are wall-clock nanoseconds (history and replay need calendar time) derived
from the monotonic clock, so they never go backwards even if NTP steps the
wall clock.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator

import numpy as np

from wott_hub.sim.scene import Scene
from wott_hub.tactile import DeviceDescription, TactileFrame

from .base import Driver, DriverError, Health, Tareable

__all__ = ["SceneDriver"]


class SceneDriver(Driver, Tareable):
    """Yields ``TactileFrame``s of ``scene`` on ``description.mesh`` at ``rate_hz``.

    ``realtime=False`` yields frames as fast as the consumer takes them, with
    timestamps still spaced by ``1 / rate_hz`` (for tests and recording a
    known sequence quickly). A non-looping scene ends after its duration.
    """

    def __init__(
        self,
        description: DeviceDescription,
        scene: Scene,
        rate_hz: float = 120.0,
        *,
        realtime: bool = True,
        max_frames: int | None = None,
    ) -> None:
        super().__init__(description)
        if not (np.isfinite(rate_hz) and rate_hz > 0):
            raise DriverError(f"rate_hz must be a positive number, got {rate_hz!r}")
        self.scene = scene
        self.rate_hz = float(rate_hz)
        self.realtime = realtime
        self.max_frames = max_frames
        self.frames_yielded = 0
        self.frames_skipped = 0
        self.tares = 0
        self._closed = asyncio.Event()


    async def frames(self) -> AsyncIterator[TactileFrame]:
        period = 1.0 / self.rate_hz
        mesh = self.description.mesh
        mono0 = time.monotonic()
        wall0_ns = time.time_ns()
        k = 0
        while not self._closed.is_set():
            if self.max_frames is not None and self.frames_yielded >= self.max_frames:
                return
            t_s = k * period
            if not self.scene.loop and t_s > self.scene.duration_s:
                return
            if self.realtime:
                delay = mono0 + t_s - time.monotonic()
                if delay > 0:
                    try:
                        await asyncio.wait_for(self._closed.wait(), delay)
                        return  # closed while waiting
                    except TimeoutError:
                        pass
                elif delay < -period:  # late by more than a frame: drop the missed ticks
                    missed = int(-delay / period)
                    k += missed
                    self.frames_skipped += missed
                    self.set_health(Health.degraded, "consumer slower than the frame rate: frames skipped")
                    await asyncio.sleep(0)  # late means the loop is busy: let the others run
                    continue
                else:
                    self.set_health(Health.ok)
                    await asyncio.sleep(0)
            else:
                await asyncio.sleep(0)  # let others run; never monopolise the loop
            frame = TactileFrame(wall0_ns + int(round(t_s * 1e9)), self.scene.displacement_at(t_s, mesh))
            k += 1
            self.frames_yielded += 1
            yield frame

    def tare(self) -> str:
        """A scene is ground truth, at rest when no step touches it: nothing to zero; the tare is recorded."""
        self.tares += 1
        return "a scripted scene has no rest offset: nothing to zero"

    async def close(self) -> None:
        self._closed.set()
